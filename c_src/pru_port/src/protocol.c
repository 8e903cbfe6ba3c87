/* See protocol.h and ../PROTOCOL.md. */
#include "protocol.h"

#include <errno.h>
#include <string.h>
#include <unistd.h>

/* ---- framing ----------------------------------------------------------- */

void frame_reader_init(struct frame_reader *r)
{
    r->start = 0;
    r->end = 0;
}

/* Moves the unconsumed bytes to the front so that a whole frame fits. */
static void compact(struct frame_reader *r)
{
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
    n = read(fd, r->buf + r->end, sizeof r->buf - r->end);
    if (n > 0)
        r->end += (size_t)n;
    return n;
}

size_t frame_reader_push(struct frame_reader *r, const void *data, size_t len)
{
    size_t room;

    compact(r);
    room = sizeof r->buf - r->end;
    if (len > room)
        len = room;
    memcpy(r->buf + r->end, data, len);
    r->end += len;
    return len;
}

bool frame_reader_next(struct frame_reader *r, const unsigned char **frame,
                       size_t *len)
{
    size_t have = r->end - r->start;
    size_t n;

    if (have < 2)
        return false;
    n = ((size_t)r->buf[r->start] << 8) | r->buf[r->start + 1];
    if (have < 2 + n)
        return false;
    *frame = r->buf + r->start + 2;
    *len = n;
    r->start += 2 + n;
    return true;
}

int frame_write(int fd, const char *payload, size_t len)
{
    unsigned char out[2 + FRAME_MAX];
    size_t total = 2 + len, done = 0;

    if (len > FRAME_MAX) {
        errno = EMSGSIZE;
        return -1;
    }
    out[0] = (unsigned char)(len >> 8);
    out[1] = (unsigned char)(len & 0xff);
    memcpy(out + 2, payload, len);
    while (done < total) {
        ssize_t w = write(fd, out + done, total - done);
        if (w < 0) {
            if (errno == EINTR)
                continue;
            return -1;
        }
        done += (size_t)w;
    }
    return 0;
}

/* ---- bounds check ------------------------------------------------------ */

/*
 * ei's decoders take no buffer length: fed a truncated or hostile frame they
 * read past its end. So before ei sees a frame, this walker proves that the
 * term is complete inside [0, len) and made only of the kinds of term a
 * request can hold. Depth is bounded so that nesting cannot blow the stack.
 */
#define TERM_MAX_DEPTH 16

static bool need(size_t i, size_t n, size_t len)
{
    return n <= len && i <= len - n;
}

static uint32_t be16(const unsigned char *p) { return ((uint32_t)p[0] << 8) | p[1]; }
static uint32_t be32(const unsigned char *p)
{
    return ((uint32_t)p[0] << 24) | ((uint32_t)p[1] << 16) | ((uint32_t)p[2] << 8) | p[3];
}

static bool term_check(const unsigned char *b, size_t len, size_t *i, int depth)
{
    size_t n;

    if (depth > TERM_MAX_DEPTH || !need(*i, 1, len))
        return false;
    switch (b[(*i)++]) {
    case ERL_SMALL_INTEGER_EXT:
        n = 1;
        break;
    case ERL_INTEGER_EXT:
        n = 4;
        break;
    case NEW_FLOAT_EXT:
        n = 8;
        break;
    case ERL_SMALL_ATOM_EXT:
    case ERL_SMALL_ATOM_UTF8_EXT:
        if (!need(*i, 1, len))
            return false;
        n = 1 + (size_t)b[*i];
        break;
    case ERL_ATOM_EXT:
    case ERL_ATOM_UTF8_EXT:
    case ERL_STRING_EXT:
        if (!need(*i, 2, len))
            return false;
        n = 2 + be16(b + *i);
        break;
    case ERL_BINARY_EXT:
        if (!need(*i, 4, len))
            return false;
        n = 4 + (size_t)be32(b + *i);
        break;
    case ERL_SMALL_BIG_EXT:
        if (!need(*i, 1, len))
            return false;
        n = 2 + (size_t)b[*i];
        break;
    case ERL_NIL_EXT:
        return true;
    case ERL_SMALL_TUPLE_EXT:
    case ERL_LARGE_TUPLE_EXT:
    case ERL_LIST_EXT: {
        unsigned char tag = b[*i - 1];
        size_t count;
        size_t head = tag == ERL_SMALL_TUPLE_EXT ? 1 : 4;

        if (!need(*i, head, len))
            return false;
        count = head == 1 ? b[*i] : be32(b + *i);
        *i += head;
        if (count > len - *i)   /* every element takes at least one byte */
            return false;
        if (tag == ERL_LIST_EXT)
            count++;            /* the tail */
        while (count-- > 0)
            if (!term_check(b, len, i, depth + 1))
                return false;
        return true;
    }
    default:
        return false;           /* pids, refs, funs, maps...: no request holds them */
    }
    if (!need(*i, n, len))
        return false;
    *i += n;
    return true;
}

/* ---- request decoding -------------------------------------------------- */

static bool d_tuple(const char *b, int *i, int arity)
{
    int a;
    return ei_decode_tuple_header(b, i, &a) == 0 && a == arity;
}

static bool d_tuple_any(const char *b, int *i, int *arity)
{
    return ei_decode_tuple_header(b, i, arity) == 0;
}

static bool d_atom(const char *b, int *i, char *out /* MAXATOMLEN */)
{
    return ei_decode_atom(b, i, out) == 0;
}

static bool d_is_atom(const char *b, int *i, const char *want)
{
    char a[MAXATOMLEN];
    return d_atom(b, i, a) && strcmp(a, want) == 0;
}

static bool d_int(const char *b, int *i, long long *v)
{
    return ei_decode_longlong(b, i, v) == 0;
}

static bool d_bool(const char *b, int *i, bool *v)
{
    int x;
    if (ei_decode_boolean(b, i, &x) != 0)
        return false;
    *v = x != 0;
    return true;
}

/* A proper list's header; the caller decodes n elements then d_list_end. */
static bool d_list(const char *b, int *i, int *n)
{
    int type, size;
    if (ei_get_type(b, i, &type, &size) != 0)
        return false;
    if (type != ERL_LIST_EXT && type != ERL_NIL_EXT)
        return false;
    return ei_decode_list_header(b, i, n) == 0;
}

static bool d_list_end(const char *b, int *i, int n)
{
    int tail;
    return n == 0 || (ei_decode_list_header(b, i, &tail) == 0 && tail == 0);
}

static bool d_servo_id(const char *b, int *i, char id[SERVO_ID_MAX])
{
    char a[MAXATOMLEN];
    if (!d_atom(b, i, a) || strlen(a) >= SERVO_ID_MAX)
        return false;
    memcpy(id, a, strlen(a) + 1);
    return true;
}

static bool decode_adc(const char *b, int *i, struct request *r, struct perr *why)
{
    int n;
    if (!d_list(b, i, &n))
        return false;
    if (n > ADC_CHANNELS) {
        perr_set_int(why, "too_many_channels", n);
        return false;
    }
    for (int k = 0; k < n; k++) {
        struct adc_config *c = &r->u.adc.ch[k];
        char mode[MAXATOMLEN];
        int arity;
        if (!d_tuple_any(b, i, &arity) || !d_int(b, i, &c->channel) || !d_atom(b, i, mode))
            return false;
        c->high = c->low = 0;
        if (arity == 2 && strcmp(mode, "analog") == 0) {
            c->mode = ADC_ANALOG;
        } else if (arity == 2 && strcmp(mode, "off") == 0) {
            c->mode = ADC_OFF;
        } else if (arity == 4 && strcmp(mode, "analog_threshold") == 0) {
            c->mode = ADC_THRESHOLD;
            if (!d_int(b, i, &c->high) || !d_int(b, i, &c->low))
                return false;
        } else {
            return false;
        }
    }
    r->u.adc.n = n;
    return d_list_end(b, i, n);
}

static bool decode_servos(const char *b, int *i, struct request *r, struct perr *why)
{
    int n;
    if (!d_list(b, i, &n))
        return false;
    if (n > MAX_SERVOS) {
        perr_set_int(why, "too_many_servos", n);
        return false;
    }
    for (int k = 0; k < n; k++) {
        struct servo_config *s = &r->u.servos.s[k];
        if (!d_tuple(b, i, 7) || !d_servo_id(b, i, s->id) || !d_int(b, i, &s->pwmchip) ||
            !d_int(b, i, &s->channel) || !d_int(b, i, &s->period_ns) ||
            !d_int(b, i, &s->neutral_ns) || !d_int(b, i, &s->span_ns) ||
            !d_bool(b, i, &s->reversed))
            return false;
    }
    r->u.servos.n = n;
    return d_list_end(b, i, n);
}

static bool decode_set(const char *b, int *i, struct request *r, struct perr *why)
{
    int n;
    if (!d_list(b, i, &n))
        return false;
    if (n > MAX_SERVOS) {
        perr_set_int(why, "too_many_servos", n);
        return false;
    }
    for (int k = 0; k < n; k++) {
        struct servo_velocity *v = &r->u.set.v[k];
        if (!d_tuple(b, i, 2) || !d_servo_id(b, i, v->id) || !d_int(b, i, &v->velocity))
            return false;
    }
    r->u.set.n = n;
    return d_list_end(b, i, n);
}

/* Decodes the request part; returns false with *why possibly set. */
static bool decode_body(const char *b, int *i, struct request *r, struct perr *why)
{
    char tag[MAXATOMLEN];
    int type, size, arity;

    if (ei_get_type(b, i, &type, &size) != 0)
        return false;
    if (type == ERL_ATOM_EXT) {
        if (!d_atom(b, i, tag))
            return false;
        if (strcmp(tag, "ping") == 0)
            r->kind = REQ_PING;
        else if (strcmp(tag, "neutral") == 0)
            r->kind = REQ_NEUTRAL;
        else {
            perr_set_atom(why, "unknown_request", tag);
            return false;
        }
        return true;
    }
    if (!d_tuple_any(b, i, &arity) || arity < 2 || !d_atom(b, i, tag))
        return false;
    perr_set_atom(why, "bad_request", tag);
    if (strcmp(tag, "configure_adc") == 0 && arity == 2) {
        r->kind = REQ_CONFIGURE_ADC;
        return decode_adc(b, i, r, why);
    }
    if (strcmp(tag, "configure_servos") == 0 && arity == 2) {
        r->kind = REQ_CONFIGURE_SERVOS;
        return decode_servos(b, i, r, why);
    }
    if (strcmp(tag, "set_servos") == 0 && arity == 2) {
        r->kind = REQ_SET_SERVOS;
        return decode_set(b, i, r, why);
    }
    if (strcmp(tag, "enable_servos") == 0 && arity == 2) {
        r->kind = REQ_ENABLE_SERVOS;
        return d_bool(b, i, &r->u.enable);
    }
    if (strcmp(tag, "configure_watchdog") == 0 && arity == 2) {
        r->kind = REQ_CONFIGURE_WATCHDOG;
        return d_int(b, i, &r->u.watchdog_ms);
    }
    if (strcmp(tag, "configure_button") == 0 && (arity == 2 || arity == 4)) {
        r->kind = REQ_CONFIGURE_BUTTON;
        r->u.button.none = arity == 2;
        if (arity == 2)
            return d_is_atom(b, i, "none");
        return d_int(b, i, &r->u.button.line) && d_bool(b, i, &r->u.button.active_low) &&
               d_int(b, i, &r->u.button.debounce_ms);
    }
    if (strcmp(tag, "sim_adc") == 0 && arity == 3) {
        r->kind = REQ_SIM_ADC;
        return d_int(b, i, &r->u.sim_adc.channel) && d_int(b, i, &r->u.sim_adc.value);
    }
    if (strcmp(tag, "sim_button") == 0 && arity == 2) {
        r->kind = REQ_SIM_BUTTON;
        return d_int(b, i, &r->u.sim_level);
    }
    perr_set_atom(why, "unknown_request", tag);
    return false;
}

enum decode_result protocol_decode(const unsigned char *frame, size_t len,
                                   struct request *req, struct perr *why)
{
    const char *b = (const char *)frame;
    size_t checked = 1;
    int i = 0, version;

    perr_clear(why);
    memset(req, 0, sizeof *req);
    if (len < 1 || len > FRAME_MAX || ei_decode_version(b, &i, &version) != 0 ||
        !term_check(frame, len, &checked, 0) || checked != len) {
        perr_set_atom(why, "bad_frame", "not_a_term");
        return DECODE_BAD_FRAME;
    }
    if (!d_tuple(b, &i, 2) || !d_int(b, &i, &req->ref)) {
        perr_set_atom(why, "bad_frame", "not_a_request");
        return DECODE_BAD_FRAME;
    }
    if (!decode_body(b, &i, req, why)) {
        if (why->reason == NULL)
            perr_set(why, "bad_request");
        return DECODE_BAD_REQUEST;
    }
    perr_clear(why);
    return DECODE_OK;
}

/* ---- encoding ---------------------------------------------------------- */

int encode_perr(ei_x_buff *x, const struct perr *e)
{
    int rc = 0;
    const char *reason = e->reason ? e->reason : "unknown";

    if (e->kind == PERR_NONE)
        return ei_x_encode_atom(x, reason);
    rc |= ei_x_encode_tuple_header(x, e->errnum ? 3 : 2);
    rc |= ei_x_encode_atom(x, reason);
    switch (e->kind) {
    case PERR_INT:
        rc |= ei_x_encode_longlong(x, e->num);
        break;
    case PERR_ATOM:
        rc |= ei_x_encode_atom(x, e->text);
        break;
    default:
        rc |= ei_x_encode_string(x, e->text);
        break;
    }
    if (e->errnum) {
        const char *a = errno_atom(e->errnum);
        rc |= a ? ei_x_encode_atom(x, a) : ei_x_encode_long(x, e->errnum);
    }
    return rc;
}

static int reply_head(ei_x_buff *x, long long ref)
{
    return ei_x_new_with_version(x) | ei_x_encode_tuple_header(x, 3) |
           ei_x_encode_atom(x, "reply") | ei_x_encode_longlong(x, ref);
}

int encode_reply_ok(ei_x_buff *x, long long ref)
{
    return encode_reply_atom(x, ref, "ok");
}

int encode_reply_atom(ei_x_buff *x, long long ref, const char *atom)
{
    return reply_head(x, ref) | ei_x_encode_atom(x, atom);
}

int encode_reply_error(ei_x_buff *x, long long ref, const struct perr *e)
{
    return reply_head(x, ref) | ei_x_encode_tuple_header(x, 2) |
           ei_x_encode_atom(x, "error") | encode_perr(x, e);
}

int encode_bad_frame(ei_x_buff *x, const struct perr *e)
{
    return ei_x_new_with_version(x) | ei_x_encode_tuple_header(x, 2) |
           ei_x_encode_atom(x, "error") | encode_perr(x, e);
}

int encode_hello(ei_x_buff *x, const char *backend)
{
    return ei_x_new_with_version(x) | ei_x_encode_tuple_header(x, 3) |
           ei_x_encode_atom(x, "hello") | ei_x_encode_long(x, PROTOCOL_VERSION) |
           ei_x_encode_atom(x, backend);
}

int encode_adc_event(ei_x_buff *x, unsigned channel, unsigned value, long long t_ms)
{
    return ei_x_new_with_version(x) | ei_x_encode_tuple_header(x, 4) |
           ei_x_encode_atom(x, "adc") | ei_x_encode_ulong(x, channel) |
           ei_x_encode_ulong(x, value) | ei_x_encode_longlong(x, t_ms);
}

int encode_button_event(ei_x_buff *x, bool pressed, long long t_ms)
{
    return ei_x_new_with_version(x) | ei_x_encode_tuple_header(x, 3) |
           ei_x_encode_atom(x, "button") |
           ei_x_encode_atom(x, pressed ? "pressed" : "released") |
           ei_x_encode_longlong(x, t_ms);
}

int encode_watchdog_event(ei_x_buff *x, long long t_ms)
{
    return ei_x_new_with_version(x) | ei_x_encode_tuple_header(x, 2) |
           ei_x_encode_atom(x, "watchdog") | ei_x_encode_longlong(x, t_ms);
}

int encode_fault_event(ei_x_buff *x, const struct perr *e)
{
    return ei_x_new_with_version(x) | ei_x_encode_tuple_header(x, 2) |
           ei_x_encode_atom(x, "fault") | encode_perr(x, e);
}

int encode_fatal(ei_x_buff *x, const struct perr *e)
{
    return ei_x_new_with_version(x) | ei_x_encode_tuple_header(x, 2) |
           ei_x_encode_atom(x, "fatal") | encode_perr(x, e);
}
