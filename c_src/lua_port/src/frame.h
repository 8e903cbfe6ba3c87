/*
 * {packet, 4} framing on a pair of file descriptors: a 4-byte big-endian
 * length, then the payload (an Erlang term in the external format).
 * Frames longer than FRAME_MAX are refused: the reader reports them and
 * skips their bytes, so one oversized frame costs one error, not the port.
 */
#ifndef LUA_PORT_FRAME_H
#define LUA_PORT_FRAME_H

#include <stdbool.h>
#include <stddef.h>
#include <sys/types.h>

#define FRAME_MAX (1u << 20)       /* 1 MiB: far more than any event */

struct frame_reader {
    unsigned char *buf;            /* FRAME_MAX + 4 bytes */
    size_t start;                  /* first unconsumed byte */
    size_t end;                    /* one past the last byte read */
    size_t skip;                   /* bytes of an oversized frame still to drop */
};

enum frame_status { FRAME_NONE, FRAME_READY, FRAME_TOO_BIG };

int frame_reader_init(struct frame_reader *r);
void frame_reader_free(struct frame_reader *r);
/* Reads what fd has ready: the byte count, 0 at end of file, -1 on error. */
ssize_t frame_reader_fill(struct frame_reader *r, int fd);
/* Appends bytes as if read (tests, fuzzing). Returns how many fitted. */
size_t frame_reader_push(struct frame_reader *r, const void *data, size_t len);
/* The next complete frame, if any; valid until the next fill or push.
 * FRAME_TOO_BIG: a frame longer than FRAME_MAX was announced and is being
 * dropped (*len is its announced length). */
enum frame_status frame_reader_next(struct frame_reader *r, const unsigned char **frame,
                                    size_t *len);
/* Writes one frame, in one write(2) when the pipe takes it. 0 or -1 (errno set). */
int frame_write(int fd, const char *payload, size_t len);

/* Frames gathered to be written together: the answers to the requests one
 * read(2) brought go back in one write(2), so that a reader woken by the
 * first finds them all (and never a length without its payload). */
struct frame_out {
    char *buf;
    size_t len, cap;
};

/* Appends one frame. 0 or -1 (errno set: EMSGSIZE, ENOMEM). */
int frame_out_add(struct frame_out *o, const char *payload, size_t len);
/* Writes every frame gathered and empties o. 0 or -1 (errno set). */
int frame_out_flush(struct frame_out *o, int fd);
void frame_out_free(struct frame_out *o);

#endif
