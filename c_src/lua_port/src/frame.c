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

int frame_write(int fd, const char *payload, size_t len)
{
    unsigned char head[4];
    const char *parts[2] = {(const char *)head, payload};
    size_t sizes[2] = {4, len};

    if (len > 0xffffffffu) {
        errno = EMSGSIZE;
        return -1;
    }
    head[0] = (unsigned char)(len >> 24);
    head[1] = (unsigned char)(len >> 16);
    head[2] = (unsigned char)(len >> 8);
    head[3] = (unsigned char)len;
    for (int k = 0; k < 2; k++) {
        size_t done = 0;
        while (done < sizes[k]) {
            ssize_t w = write(fd, parts[k] + done, sizes[k] - done);
            if (w < 0) {
                if (errno == EINTR)
                    continue;
                return -1;
            }
            done += (size_t)w;
        }
    }
    return 0;
}
