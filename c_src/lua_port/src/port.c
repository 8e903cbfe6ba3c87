/* See port.h and ../PROTOCOL.md. */
#include "port.h"

#include <errno.h>
#include <limits.h>
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

/* A request's Id: one Lua behavior, the slot it is of a Lua state. */
struct entry {
    long long id;
    struct lstate *s;
    int slot;
};

struct port {
    struct entry *entries;
    int n, cap;
    struct lstate **states;      /* every state, each once */
    int n_states, cap_states;
};

struct port *port_new(void)
{
    return calloc(1, sizeof(struct port));
}

void port_free(struct port *p)
{
    if (p == NULL)
        return;
    for (int k = 0; k < p->n_states; k++)
        lstate_close(p->states[k]);
    free(p->states);
    free(p->entries);
    free(p);
}

int port_states(const struct port *p)
{
    return p->n;
}

static int find(const struct port *p, long long id)
{
    for (int k = 0; k < p->n; k++)
        if (p->entries[k].id == id)
            return k;
    return -1;
}

/* The state opened as `id' (its first behavior's id), whoever holds it now. */
static struct lstate *find_state(const struct port *p, long long id)
{
    for (int k = 0; k < p->n_states; k++)
        if (p->states[k]->id == id)
            return p->states[k];
    return NULL;
}

static bool grow(void **arr, int *cap, int n, size_t size)
{
    if (n < *cap)
        return true;
    int c = *cap ? 2 * *cap : 16;
    void *grown = realloc(*arr, (size_t)c * size);
    if (grown == NULL)
        return false;
    *arr = grown;
    *cap = c;
    return true;
}

static bool add_entry(struct port *p, long long id, struct lstate *s, int slot)
{
    if (!grow((void **)&p->entries, &p->cap, p->n, sizeof *p->entries))
        return false;
    p->entries[p->n++] = (struct entry){.id = id, .s = s, .slot = slot};
    return true;
}

static bool add_state(struct port *p, struct lstate *s)
{
    if (!grow((void **)&p->states, &p->cap_states, p->n_states, sizeof *p->states))
        return false;
    p->states[p->n_states++] = s;
    return true;
}

/* A state no slot holds any more and no entry names is closed. */
static void collect(struct port *p, struct lstate *s)
{
    if (s->refs > 0)
        return;
    for (int k = 0; k < p->n; k++)
        if (p->entries[k].s == s)
            return;
    for (int k = 0; k < p->n_states; k++)
        if (p->states[k] == s) {
            p->states[k] = p->states[--p->n_states];
            break;
        }
    lstate_close(s);
}

/* Entry k goes. `release': its behavior is gone for good (closed, or slot
 * 0 stopped: a file's behavior starts again in a new state); otherwise its
 * slot stays held for the behavior's restart. */
static void drop(struct port *p, int k, bool release)
{
    struct lstate *s = p->entries[k].s;
    int slot = p->entries[k].slot;

    p->entries[k] = p->entries[--p->n];
    (void)lstate_detach(s, slot, release);
    collect(p, s);
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
    struct lstate *s = p->entries[k].s;
    int slot = p->entries[k].slot;

    reply_head(x, ref);
    if (s->failed || s->dead) {
        ei_x_encode_tuple_header(x, 3);
        ei_x_encode_atom(x, "stopped");
        lstate_encode_failure(s, x);
        lstate_take_actions(s, x);
        /* an error or the budget ends this slot's behavior only; the memory
         * cap ends the state, and each of its behaviors at its next request */
        if (!s->dead && !lstate_recover(s))
            s->dead = true;
        drop(p, k, slot == 0 || s->dead);
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
    if (find(p, id) >= 0 || find_state(p, id) != NULL)
        { reply_error(x, ref, "duplicate_state", id); return; }
    if (p->n_states >= MAX_STATES || p->n >= MAX_STATES)
        { reply_error(x, ref, "too_many_states", id); return; }
    struct lstate_opts o = {.file = file, .dir = dir, .budget = (unsigned long)budget,
                            .mem_cap = (size_t)mem};
    s = lstate_open(id, &o, &params, now);
    if (s == NULL || !add_state(p, s)) {
        lstate_close(s);
        { reply_error(x, ref, "out_of_memory", id); return; }
    }
    if (!add_entry(p, id, s, 0)) {
        p->n_states--;
        lstate_close(s);
        { reply_error(x, ref, "out_of_memory", id); return; }
    }
    activation_reply(p, p->n - 1, x, ref);
}

static void do_attach(struct port *p, struct term_reader *r, size_t arity, long long ref,
                      ei_x_buff *x)
{
    long long id, host, slot, now;
    struct lstate *s;

    /* {attach, Ref, Id, Host, Slot, Now} */
    if (arity != 6 || !term_integer(r, &id) || !term_integer(r, &host) ||
        !term_integer(r, &slot) || !term_integer(r, &now) || slot <= 0 || slot > INT_MAX / 2)
        { reply_error(x, ref, "bad_request", ref); return; }
    if (find(p, id) >= 0 || find_state(p, id) != NULL)
        { reply_error(x, ref, "duplicate_state", id); return; }
    if ((s = find_state(p, host)) == NULL || s->dead)
        { reply_error(x, ref, "unknown_state", host); return; }
    if (p->n >= MAX_STATES)
        { reply_error(x, ref, "too_many_states", id); return; }
    /* the slot's behavior starting again in its process (a Brooks reset):
     * the entry it had goes, the slot stays held, its tasks start anew */
    for (int k = 0; k < p->n; k++)
        if (p->entries[k].s == s && p->entries[k].slot == (int)slot) {
            p->entries[k] = p->entries[--p->n];
            (void)lstate_detach(s, (int)slot, false);
            break;
        }
    if (!add_entry(p, id, s, (int)slot))
        { reply_error(x, ref, "out_of_memory", id); return; }
    if (!lstate_attach(s, (int)slot, now)) {
        p->n--;
        { reply_error(x, ref, "unknown_slot", slot); return; }
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
    if (!lstate_input_slot(p->entries[k].s, p->entries[k].slot, input, r, now))
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
    lstate_timer(p->entries[k].s, task, seq, now);
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
        drop(p, k, true);
        ei_x_encode_atom(x, "ok");
        return;
    }
    ei_x_encode_tuple_header(x, 2);
    ei_x_encode_atom(x, "ok");
    if (strcmp(op, "waits") == 0)
        lstate_waits_slot(p->entries[k].s, p->entries[k].slot, x);
    else
        ei_x_encode_ulonglong(x, p->entries[k].s->mem);
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
    } else if (strcmp(op, "attach") == 0) {
        do_attach(p, &r, arity, ref, x);
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
