/*
 * The port protocol: {packet, 2} framing on a pair of file descriptors and
 * the Erlang terms inside the frames (decoded and encoded with ei). The
 * frame set is written down in ../PROTOCOL.md; keep the two in step.
 *
 * Nothing here touches hardware or the clock: a frame in, a struct out;
 * a struct in, a frame out. That is what makes it testable and fuzzable.
 */
#ifndef PROTOCOL_H
#define PROTOCOL_H

#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>
#include <sys/types.h>

#include <ei.h>

#include "adc.h"
#include "error.h"
#include "pwm.h"

#define PROTOCOL_VERSION 1
#define FRAME_MAX 65535u          /* {packet, 2} */

/* ---- framing ----------------------------------------------------------- */

struct frame_reader {
    unsigned char buf[2 * (FRAME_MAX + 2)];
    size_t start;                 /* first unconsumed byte */
    size_t end;                   /* one past the last byte read */
};

void frame_reader_init(struct frame_reader *r);
/* Reads what fd has ready. Returns the byte count, 0 at end of file, -1 on
 * error (errno set; EAGAIN/EINTR are the caller's to retry). */
ssize_t frame_reader_fill(struct frame_reader *r, int fd);
/* Appends bytes as if read (tests, fuzzing). Returns how many fitted. */
size_t frame_reader_push(struct frame_reader *r, const void *data, size_t len);
/* The next complete frame, if any; valid until the next fill or push. */
bool frame_reader_next(struct frame_reader *r, const unsigned char **frame,
                       size_t *len);
/* Writes one frame (2-byte big-endian length, then the payload). 0 or -1. */
int frame_write(int fd, const char *payload, size_t len);

/* ---- requests ---------------------------------------------------------- */

enum request_kind {
    REQ_PING,
    REQ_CONFIGURE_ADC,
    REQ_CONFIGURE_SERVOS,
    REQ_SET_SERVOS,
    REQ_ENABLE_SERVOS,
    REQ_NEUTRAL,
    REQ_CONFIGURE_WATCHDOG,
    REQ_CONFIGURE_BUTTON,
    REQ_SIM_ADC,
    REQ_SIM_BUTTON
};

struct request {
    long long ref;
    enum request_kind kind;
    union {
        struct { int n; struct adc_config ch[ADC_CHANNELS]; } adc;
        struct { int n; struct servo_config s[MAX_SERVOS]; } servos;
        struct { int n; struct servo_velocity v[MAX_SERVOS]; } set;
        bool enable;
        long long watchdog_ms;
        struct { bool none; long long line; bool active_low; long long debounce_ms; } button;
        struct { long long channel; long long value; } sim_adc;
        long long sim_level;
    } u;
};

enum decode_result {
    DECODE_OK,
    DECODE_BAD_FRAME,   /* no usable reference: answer with {error, {bad_frame, Why}} */
    DECODE_BAD_REQUEST  /* req->ref is valid: answer {reply, Ref, {error, Why}} */
};

/* Decodes one frame. Never reads outside frame[0..len). */
enum decode_result protocol_decode(const unsigned char *frame, size_t len,
                                   struct request *req, struct perr *why);

/* ---- replies and events (each into a fresh ei_x_buff owned by caller) --- */

int encode_reply_ok(ei_x_buff *x, long long ref);
int encode_reply_atom(ei_x_buff *x, long long ref, const char *atom);
int encode_reply_error(ei_x_buff *x, long long ref, const struct perr *e);
int encode_bad_frame(ei_x_buff *x, const struct perr *e);
int encode_hello(ei_x_buff *x, const char *backend);
int encode_adc_event(ei_x_buff *x, unsigned channel, unsigned value, long long t_ms);
int encode_button_event(ei_x_buff *x, bool pressed, long long t_ms);
int encode_watchdog_event(ei_x_buff *x, long long t_ms);
int encode_fault_event(ei_x_buff *x, const struct perr *e);
/* {fatal, Reason}: the last frame of a program that cannot start. */
int encode_fatal(ei_x_buff *x, const struct perr *e);
/* The reason term alone (used inside the above; exposed for tests). */
int encode_perr(ei_x_buff *x, const struct perr *e);

#endif
