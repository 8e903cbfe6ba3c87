/* See frame.h. */
#include "frame.h"

#include <errno.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#define BUF_SIZE (FRAME_MAX + 4)

int frame_reader_init(struct frame_reader *r)
{
    r->buf = malloc(BUF_SIZE);
    r->start = r->end = r->skip = 0;
    return r->buf == NULL ? -1 : 0;
}

void frame_reader_free(struct frame_reader *r)
{
    free(r->buf);
    r->buf = NULL;
}

/* Drops the bytes of an oversized frame, then moves the rest to the front. */
static void compact(struct frame_reader *r)
{
    size_t have = r->end - r->start;
    size_t drop = r->skip < have ? r->skip : have;

    r->start += drop;
    r->skip -= drop;
    if (r->start == 0)
        return;
    memmove(r->buf, r->buf + r->start, r->end - r->start);
    r->end -= r->start;
    r->start = 0;
}

ssize_t frame_reader_fill(struct frame_reader *r, int fd)
{
    ssize_t n;

    compact(r);
    n = read(fd, r->buf + r->end, BUF_SIZE - r->end);
    if (n > 0)
        r->end += (size_t)n;
    return n;
}

size_t frame_reader_push(struct frame_reader *r, const void *data, size_t len)
{
    size_t room;

    compact(r);
    room = BUF_SIZE - r->end;
    if (len > room)
        len = room;
    memcpy(r->buf + r->end, data, len);
    r->end += len;
    return len;
}

enum frame_status frame_reader_next(struct frame_reader *r, const unsigned char **frame,
                                    size_t *len)
{
    size_t have, n;
    const unsigned char *p;

    have = r->end - r->start;
    if (r->skip > 0) {            /* still dropping an oversized frame */
        size_t drop = r->skip < have ? r->skip : have;
        r->start += drop;
        r->skip -= drop;
        have -= drop;
    }
    if (r->skip > 0 || have < 4)
        return FRAME_NONE;
    p = r->buf + r->start;
    n = ((size_t)p[0] << 24) | ((size_t)p[1] << 16) | ((size_t)p[2] << 8) | p[3];
    if (n > FRAME_MAX) {
        r->start += 4;
        r->skip = n;
        *len = n;
        return FRAME_TOO_BIG;
    }
    if (have - 4 < n)
        return FRAME_NONE;
    *frame = p + 4;
    *len = n;
    r->start += 4 + n;
    return FRAME_READY;
}

static void put_len(unsigned char head[4], size_t len)
{
    head[0] = (unsigned char)(len >> 24);
    head[1] = (unsigned char)(len >> 16);
    head[2] = (unsigned char)(len >> 8);
    head[3] = (unsigned char)len;
}

/* Writes all of buf, across partial writes and signals. */
static int write_all(int fd, const char *buf, size_t len)
{
    size_t done = 0;

    while (done < len) {
        ssize_t w = write(fd, buf + done, len - done);
        if (w < 0) {
            if (errno == EINTR)
                continue;
            return -1;
        }
        done += (size_t)w;
    }
    return 0;
}

int frame_write(int fd, const char *payload, size_t len)
{
    struct frame_out o = {0};
    int rc;

    if (frame_out_add(&o, payload, len) != 0)
        return -1;
    rc = frame_out_flush(&o, fd);
    frame_out_free(&o);
    return rc;
}

int frame_out_add(struct frame_out *o, const char *payload, size_t len)
{
    if (len > 0xffffffffu) {
        errno = EMSGSIZE;
        return -1;
    }
    if (o->cap - o->len < len + 4) {
        size_t cap = o->cap ? o->cap : 4096;
        while (cap - o->len < len + 4)
            cap *= 2;
        char *grown = realloc(o->buf, cap);
        if (grown == NULL) {
            errno = ENOMEM;
            return -1;
        }
        o->buf = grown;
        o->cap = cap;
    }
    put_len((unsigned char *)o->buf + o->len, len);
    memcpy(o->buf + o->len + 4, payload, len);
    o->len += len + 4;
    return 0;
}

int frame_out_flush(struct frame_out *o, int fd)
{
    int rc = write_all(fd, o->buf, o->len);
    o->len = 0;
    return rc;
}

void frame_out_free(struct frame_out *o)
{
    free(o->buf);
    o->buf = NULL;
    o->len = o->cap = 0;
}
