/* See port.h and ../PROTOCOL.md. */
#include "port.h"

#include <errno.h>
#include <poll.h>
#include <signal.h>
#include <time.h>
#include <stdbool.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "frame.h"
#include "lstate.h"
#include "term.h"

struct port {
    struct lstate **states;
    int n, cap;
};

struct port *port_new(void)
{
    return calloc(1, sizeof(struct port));
}

void port_free(struct port *p)
{
    if (p == NULL)
        return;
    for (int k = 0; k < p->n; k++)
        lstate_close(p->states[k]);
    free(p->states);
    free(p);
}

int port_states(const struct port *p)
{
    return p->n;
}

static int find(const struct port *p, long long id)
{
    for (int k = 0; k < p->n; k++)
        if (p->states[k]->id == id)
            return k;
    return -1;
}

static void drop(struct port *p, int k)
{
    lstate_close(p->states[k]);
    p->states[k] = p->states[--p->n];
}

static bool add(struct port *p, struct lstate *s)
{
    if (p->n == p->cap) {
        int cap = p->cap ? 2 * p->cap : 16;
        struct lstate **grown = realloc(p->states, (size_t)cap * sizeof *grown);
        if (grown == NULL)
            return false;
        p->states = grown;
        p->cap = cap;
    }
    p->states[p->n++] = s;
    return true;
}

/* ---- replies ----------------------------------------------------------- */

static void reply_head(ei_x_buff *x, long long ref)
{
    ei_x_encode_tuple_header(x, 3);
    ei_x_encode_atom(x, "reply");
    ei_x_encode_longlong(x, ref);
}

static void reply_error(ei_x_buff *x, long long ref, const char *why, long long subject)
{
    reply_head(x, ref);
    ei_x_encode_tuple_header(x, 2);
    ei_x_encode_atom(x, "error");
    ei_x_encode_tuple_header(x, 2);
    ei_x_encode_atom(x, why);
    ei_x_encode_longlong(x, subject);
}

static void bad_frame(ei_x_buff *x, const char *why)
{
    ei_x_encode_tuple_header(x, 2);
    ei_x_encode_atom(x, "bad_frame");
    ei_x_encode_atom(x, why);
}

void port_too_big(ei_x_buff *x, size_t len)
{
    ei_x_new_with_version(x);
    ei_x_encode_tuple_header(x, 2);
    ei_x_encode_atom(x, "bad_frame");
    ei_x_encode_tuple_header(x, 2);
    ei_x_encode_atom(x, "too_big");
    ei_x_encode_ulonglong(x, len);
}

/* After an activation: {ok, Actions}, or {stopped, Reason, Actions} and the
 * state is gone. */
static void activation_reply(struct port *p, int k, ei_x_buff *x, long long ref)
{
    struct lstate *s = p->states[k];

    reply_head(x, ref);
    if (s->failed) {
        ei_x_encode_tuple_header(x, 3);
        ei_x_encode_atom(x, "stopped");
        lstate_encode_failure(s, x);
        lstate_take_actions(s, x);
        drop(p, k);
    } else {
        ei_x_encode_tuple_header(x, 2);
        ei_x_encode_atom(x, "ok");
        lstate_take_actions(s, x);
    }
}

/* ---- requests ---------------------------------------------------------- */

/* A binary holding a path: no NUL, shorter than PATH_MAX. */
static bool path_term(struct term_reader *r, char out[PATH_MAX])
{
    const unsigned char *b;
    size_t n;

    if (!term_binary(r, &b, &n) || n == 0 || n >= PATH_MAX || memchr(b, 0, n) != NULL)
        return false;
    memcpy(out, b, n);
    out[n] = '\0';
    return true;
}

/* An input's name: an atom or a binary, as a C string. */
static bool name_term(struct term_reader *r, char out[TERM_ATOM_MAX])
{
    struct term_reader save = *r;
    const unsigned char *b;
    size_t n;

    if (term_atom(r, out))
        return true;
    *r = save;
    if (!term_binary(r, &b, &n) || n >= TERM_ATOM_MAX || memchr(b, 0, n) != NULL)
        return false;
    memcpy(out, b, n);
    out[n] = '\0';
    return true;
}

static void do_open(struct port *p, struct term_reader *r, size_t arity, long long ref,
                    ei_x_buff *x)
{
    long long id, now, budget, mem;
    char file[PATH_MAX], dir[PATH_MAX];
    struct term_reader params;
    struct lstate *s;

    /* {open, Ref, Id, Now, File, Dir, Params, Budget, Mem} */
    if (arity != 9 || !term_integer(r, &id) || !term_integer(r, &now) ||
        !path_term(r, file) || !path_term(r, dir))
        { reply_error(x, ref, "bad_request", ref); return; }
    params = *r;
    if (!term_skip(r) || !term_integer(r, &budget) || !term_integer(r, &mem) ||
        budget <= 0 || mem <= 0)
        { reply_error(x, ref, "bad_request", ref); return; }
    if (find(p, id) >= 0)
        { reply_error(x, ref, "duplicate_state", id); return; }
    if (p->n >= MAX_STATES)
        { reply_error(x, ref, "too_many_states", id); return; }
    struct lstate_opts o = {.file = file, .dir = dir, .budget = (unsigned long)budget,
                            .mem_cap = (size_t)mem};
    s = lstate_open(id, &o, &params, now);
    if (s == NULL || !add(p, s)) {
        lstate_close(s);
        { reply_error(x, ref, "out_of_memory", id); return; }
    }
    activation_reply(p, p->n - 1, x, ref);
}

static void do_input(struct port *p, struct term_reader *r, size_t arity, long long ref,
                     ei_x_buff *x)
{
    long long id, now;
    char input[TERM_ATOM_MAX];
    int k;

    /* {input, Ref, Id, Now, Input, Value} */
    if (arity != 6 || !term_integer(r, &id) || !term_integer(r, &now) || !name_term(r, input))
        { reply_error(x, ref, "bad_request", ref); return; }
    if ((k = find(p, id)) < 0)
        { reply_error(x, ref, "unknown_state", id); return; }
    if (!lstate_input(p->states[k], input, r, now))
        { reply_error(x, ref, "bad_value", id); return; }
    activation_reply(p, k, x, ref);
}

static void do_timer(struct port *p, struct term_reader *r, size_t arity, long long ref,
                     ei_x_buff *x)
{
    long long id, now, task, seq;
    int k;

    /* {timer, Ref, Id, Now, Task, Seq} */
    if (arity != 6 || !term_integer(r, &id) || !term_integer(r, &now) ||
        !term_integer(r, &task) || !term_integer(r, &seq))
        { reply_error(x, ref, "bad_request", ref); return; }
    if ((k = find(p, id)) < 0)
        { reply_error(x, ref, "unknown_state", id); return; }
    lstate_timer(p->states[k], task, seq, now);
    activation_reply(p, k, x, ref);
}

/* {close, Ref, Id} | {waits, Ref, Id} | {memory, Ref, Id} */
static void do_on_state(struct port *p, const char *op, struct term_reader *r, size_t arity,
                        long long ref, ei_x_buff *x)
{
    long long id;
    int k;

    if (arity != 3 || !term_integer(r, &id))
        { reply_error(x, ref, "bad_request", ref); return; }
    if ((k = find(p, id)) < 0)
        { reply_error(x, ref, "unknown_state", id); return; }
    reply_head(x, ref);
    if (strcmp(op, "close") == 0) {
        drop(p, k);
        ei_x_encode_atom(x, "ok");
        return;
    }
    ei_x_encode_tuple_header(x, 2);
    ei_x_encode_atom(x, "ok");
    if (strcmp(op, "waits") == 0)
        lstate_waits(p->states[k], x);
    else
        ei_x_encode_ulonglong(x, p->states[k]->mem);
}

void port_handle(struct port *p, const unsigned char *frame, size_t len, ei_x_buff *x)
{
    struct term_reader r, whole;
    size_t arity;
    char op[TERM_ATOM_MAX];
    long long ref;

    ei_x_new_with_version(x);
    /* the whole frame must be one complete term before anything is read */
    term_reader_init(&whole, frame, len);
    if (!term_version(&whole) || !term_skip(&whole) || whole.i != len)
        { bad_frame(x, "not_a_term"); return; }
    term_reader_init(&r, frame, len);
    (void)term_version(&r);
    if (!term_tuple(&r, &arity) || arity < 2 || !term_atom(&r, op) || !term_integer(&r, &ref))
        { bad_frame(x, "not_a_request"); return; }
    if (strcmp(op, "ping") == 0 && arity == 2) {
        reply_head(x, ref);
        ei_x_encode_tuple_header(x, 2);
        ei_x_encode_atom(x, "pong");
        ei_x_encode_long(x, PROTOCOL_VERSION);
    } else if (strcmp(op, "open") == 0) {
        do_open(p, &r, arity, ref, x);
    } else if (strcmp(op, "input") == 0) {
        do_input(p, &r, arity, ref, x);
    } else if (strcmp(op, "timer") == 0) {
        do_timer(p, &r, arity, ref, x);
    } else if (strcmp(op, "close") == 0 || strcmp(op, "waits") == 0 ||
               strcmp(op, "memory") == 0) {
        do_on_state(p, op, &r, arity, ref, x);
    } else {
        reply_error(x, ref, "bad_request", ref);
    }
}

/* ---- the loop ---------------------------------------------------------- */

#define OUT_FLUSH (64u << 10)        /* answers gathered past this go out at once */
#define OUT_HOLD_US 500              /* nor, after an activation, held longer than this */

static long long now_us(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (long long)t.tv_sec * 1000000 + t.tv_nsec / 1000;
}

/* Waits up to spin_us for input without sleeping: the next request of an
 * event stream comes within microseconds of the last answer, and a program
 * asleep in read(2) takes a wake-up to get it. */
static void spin(int fd, long spin_us)
{
    struct pollfd pfd = {.fd = fd, .events = POLLIN};
    long long until;

    if (spin_us <= 0)
        return;
    until = now_us() + spin_us;
    do {
        if (poll(&pfd, 1, 0) != 0)
            return;
    } while (now_us() < until);
}

int port_run(int in_fd, int out_fd)
{
    return port_run_spin(in_fd, out_fd, 0);
}

int port_run_spin(int in_fd, int out_fd, long spin_us)
{
    struct port *p = port_new();
    struct frame_reader in;
    struct frame_out out = {0};
    int rc = 0;

    if (p == NULL || frame_reader_init(&in) != 0) {
        port_free(p);
        return 1;
    }
    signal(SIGPIPE, SIG_IGN);        /* a dead owner shows as EPIPE on write */
    for (;;) {
        spin(in_fd, spin_us);
        ssize_t n = frame_reader_fill(&in, in_fd);
        const unsigned char *frame;
        size_t len;
        enum frame_status st;

        if (n == 0)
            break;                    /* the owner closed the port */
        if (n < 0) {
            if (errno == EINTR || errno == EAGAIN)
                continue;
            rc = 1;
            break;
        }
        /* the answers to what this read brought, written together; those
         * held longer than OUT_HOLD_US go out after the activation that made
         * them wait, so that a batch of slow activations answers as it goes
         * (an answer before a long one still waits for that one, at most
         * its budget) */
        long long held_since = 0;
        while ((st = frame_reader_next(&in, &frame, &len)) != FRAME_NONE) {
            ei_x_buff x;
            if (st == FRAME_TOO_BIG)
                port_too_big(&x, len);
            else
                port_handle(p, frame, len, &x);
            if (out.len > 0 && now_us() - held_since > OUT_HOLD_US &&
                frame_out_flush(&out, out_fd) != 0) {
                ei_x_free(&x);
                rc = 1;
                goto out;
            }
            if (out.len == 0)
                held_since = now_us();
            int w = frame_out_add(&out, x.buff, (size_t)x.index);
            ei_x_free(&x);
            if (w != 0 || (out.len >= OUT_FLUSH && frame_out_flush(&out, out_fd) != 0)) {
                rc = 1;
                goto out;
            }
        }
        if (out.len > 0 && frame_out_flush(&out, out_fd) != 0) {
            rc = 1;
            break;
        }
    }
out:
    frame_out_free(&out);
    frame_reader_free(&in);
    port_free(p);
    return rc;
}
