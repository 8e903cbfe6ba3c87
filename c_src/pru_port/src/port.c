#include "port.h"

#include <errno.h>
#include <poll.h>
#include <signal.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "protocol.h"
#include "pwm.h"
#include "watchdog.h"

struct port {
    const struct port_opts *opts;
    int out_fd;
    bool out_broken;              /* the owner is gone: stop */
    struct frame_reader in;
    struct adc_bank adc;
    struct pwm_bank pwm;
    struct watchdog watchdog;
    struct button button;
    struct backend backend;
    struct backend_sink sink;
};

static volatile sig_atomic_t stop_signal;

long long clock_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (long long)ts.tv_sec * 1000 + ts.tv_nsec / 1000000;
}

void port_opts_defaults(struct port_opts *o)
{
    o->backend = "sim";
    o->sysfs_root = "/sys";
    o->gpiochip = "/dev/gpiochip0";
    o->watchdog_ms = 0;
    o->sim_script = NULL;
    o->remoteproc = "class/remoteproc/remoteproc1";
    o->firmware = NULL;
    o->rpmsg_dev = "/dev/rpmsg_pru30";
    o->rpmsg_wait_ms = 3000;
}

static bool parse_ms(const char *s, long long *out)
{
    char *end;
    long long v;

    errno = 0;
    v = strtoll(s, &end, 10);
    if (errno != 0 || *s == '\0' || *end != '\0' || v < 0)
        return false;
    *out = v;
    return true;
}

int port_opts_parse(struct port_opts *o, int argc, char **argv, struct perr *e)
{
    for (int i = 1; i < argc; i++) {
        const char *k = argv[i];
        const char *v = i + 1 < argc ? argv[i + 1] : NULL;

        if (v == NULL) {
            perr_set_path(e, "bad_argument", k, 0);
            return -1;
        }
        i++;
        if (strcmp(k, "--backend") == 0 && backend_lookup(v) != NULL)
            o->backend = v;
        else if (strcmp(k, "--sysfs-root") == 0)
            o->sysfs_root = v;
        else if (strcmp(k, "--gpiochip") == 0)
            o->gpiochip = v;
        else if (strcmp(k, "--sim-script") == 0)
            o->sim_script = v;
        else if (strcmp(k, "--remoteproc") == 0)
            o->remoteproc = v;
        else if (strcmp(k, "--firmware") == 0)
            o->firmware = v;
        else if (strcmp(k, "--rpmsg-dev") == 0)
            o->rpmsg_dev = v;
        else if (strcmp(k, "--watchdog-ms") == 0 && parse_ms(v, &o->watchdog_ms))
            ;
        else if (strcmp(k, "--rpmsg-wait-ms") == 0 && parse_ms(v, &o->rpmsg_wait_ms))
            ;
        else {
            perr_set_path(e, "bad_argument", k, 0);
            return -1;
        }
    }
    return 0;
}

/* ---- output ------------------------------------------------------------ */

static void send_x(struct port *p, ei_x_buff *x, int encode_rc)
{
    if (encode_rc == 0 && !p->out_broken && frame_write(p->out_fd, x->buff, (size_t)x->index) != 0)
        p->out_broken = true;
    ei_x_free(x);
}

static void on_adc(void *ctx, unsigned channel, unsigned value, long long now_ms)
{
    ei_x_buff x;
    send_x(ctx, &x, encode_adc_event(&x, channel, value, now_ms));
}

static void on_button(void *ctx, enum button_edge edge, long long now_ms)
{
    ei_x_buff x;
    send_x(ctx, &x, encode_button_event(&x, edge == BUTTON_PRESSED, now_ms));
}

static void on_fault(void *ctx, const struct perr *e)
{
    ei_x_buff x;
    send_x(ctx, &x, encode_fault_event(&x, e));
}

/* The safe state. Called before anything else is done about a failure. */
static void go_neutral(struct port *p)
{
    struct perr e;

    perr_clear(&e);
    if (pwm_neutral(&p->pwm, &e) != 0)
        on_fault(p, &e);
}

/* ---- requests ---------------------------------------------------------- */

static int handle(struct port *p, const struct request *r, long long now, struct perr *e)
{
    const struct backend *b = &p->backend;

    switch (r->kind) {
    case REQ_PING:
        return 0;
    case REQ_NEUTRAL:
        return pwm_neutral(&p->pwm, e);
    case REQ_CONFIGURE_ADC:
        if (adc_configure(&p->adc, r->u.adc.ch, r->u.adc.n, e) != 0)
            return -1;
        return b->ops->configure_adc(&p->backend, e);
    case REQ_CONFIGURE_SERVOS:
        return pwm_configure(&p->pwm, r->u.servos.s, r->u.servos.n, e);
    case REQ_SET_SERVOS:
        if (pwm_set(&p->pwm, r->u.set.v, r->u.set.n, e) != 0)
            return -1;
        watchdog_kick(&p->watchdog, now);
        return 0;
    case REQ_ENABLE_SERVOS:
        if (pwm_enable(&p->pwm, r->u.enable, e) != 0)
            return -1;
        watchdog_kick(&p->watchdog, now);
        return 0;
    case REQ_CONFIGURE_WATCHDOG:
        if (r->u.watchdog_ms < 0 || r->u.watchdog_ms > 24LL * 3600 * 1000) {
            perr_set_int(e, "bad_watchdog", r->u.watchdog_ms);
            return -1;
        }
        watchdog_set_period(&p->watchdog, r->u.watchdog_ms, now);
        return 0;
    case REQ_CONFIGURE_BUTTON:
        if (r->u.button.none) {
            button_close(&p->button);
            return 0;
        }
        if (r->u.button.debounce_ms < 0 || r->u.button.debounce_ms > 10000) {
            perr_set_int(e, "bad_debounce", r->u.button.debounce_ms);
            return -1;
        }
        return b->ops->configure_button(&p->backend, r->u.button.line,
                                        r->u.button.active_low, r->u.button.debounce_ms, e);
    case REQ_SIM_ADC:
        return b->ops->sim_adc(&p->backend, r->u.sim_adc.channel, r->u.sim_adc.value, now,
                               &p->sink, e);
    case REQ_SIM_BUTTON:
        return b->ops->sim_button(&p->backend, r->u.sim_level, now, &p->sink, e);
    }
    perr_set(e, "bad_request");
    return -1;
}

static void on_frame(struct port *p, const unsigned char *frame, size_t len, long long now)
{
    struct request r;
    struct perr e;
    ei_x_buff x;

    switch (protocol_decode(frame, len, &r, &e)) {
    case DECODE_BAD_FRAME:
        go_neutral(p);
        send_x(p, &x, encode_bad_frame(&x, &e));
        return;
    case DECODE_BAD_REQUEST:
        go_neutral(p);
        send_x(p, &x, encode_reply_error(&x, r.ref, &e));
        return;
    case DECODE_OK:
        break;
    }
    perr_clear(&e);
    if (handle(p, &r, now, &e) != 0)
        send_x(p, &x, encode_reply_error(&x, r.ref, &e));
    else if (r.kind == REQ_PING)
        send_x(p, &x, encode_reply_atom(&x, r.ref, "pong"));
    else
        send_x(p, &x, encode_reply_ok(&x, r.ref));
}

/* ---- the loop ---------------------------------------------------------- */

static void on_signal(int sig)
{
    stop_signal = sig;
}

static void install_signals(void)
{
    struct sigaction sa;

    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal;   /* no SA_RESTART: poll() must return */
    sigemptyset(&sa.sa_mask);
    sigaction(SIGTERM, &sa, NULL);
    sigaction(SIGINT, &sa, NULL);
    sigaction(SIGHUP, &sa, NULL);
    sa.sa_handler = SIG_IGN;     /* a dead owner shows as EPIPE on write */
    sigaction(SIGPIPE, &sa, NULL);
}

static long long earliest(long long a, long long b)
{
    if (a < 0)
        return b;
    if (b < 0)
        return a;
    return a < b ? a : b;
}

static int poll_timeout(struct port *p, long long now)
{
    long long t = earliest(watchdog_timeout(&p->watchdog, now),
                           earliest(p->backend.ops->timeout(&p->backend, now),
                                    button_timeout(&p->button, now)));
    return t > 60000 ? 60000 : (int)t;
}

static void run_timers(struct port *p, long long now)
{
    enum button_edge edge;

    if (watchdog_expired(&p->watchdog, now)) {
        go_neutral(p);
        ei_x_buff x;
        send_x(p, &x, encode_watchdog_event(&x, now));
    }
    edge = button_settle(&p->button, now);
    if (edge != BUTTON_NONE)
        on_button(p, edge, now);
}

/* Reads and handles what the owner sent. -1 to go on; otherwise the loop
 * ends with this exit code (0: end of input, the owner closed the port). */
static int read_input(struct port *p, int in_fd, long long now)
{
    const unsigned char *frame;
    size_t len;
    ssize_t n = frame_reader_fill(&p->in, in_fd);

    if (n == 0)
        return 0;
    if (n < 0 && errno != EINTR && errno != EAGAIN)
        return 1;
    while (frame_reader_next(&p->in, &frame, &len))
        on_frame(p, frame, len, now);
    return -1;
}

static void read_button(struct port *p, long long now)
{
    struct perr e;
    enum button_edge edge;

    perr_clear(&e);
    edge = button_read_gpiod(&p->button, now, &e);
    if (e.reason != NULL) {
        on_fault(p, &e);
        button_close(&p->button);
    } else if (edge != BUTTON_NONE) {
        on_button(p, edge, now);
    }
}

int port_run(const struct port_opts *o, int in_fd, int out_fd)
{
    struct port *p = calloc(1, sizeof *p);
    struct perr e;
    ei_x_buff x;
    int rc = 0;

    if (p == NULL)
        return 1;
    install_signals();
    p->opts = o;
    p->out_fd = out_fd;
    frame_reader_init(&p->in);
    adc_init(&p->adc);
    pwm_init(&p->pwm, o->sysfs_root);
    watchdog_init(&p->watchdog, o->watchdog_ms);
    button_init(&p->button);
    p->sink = (struct backend_sink){.ctx = p, .adc = on_adc, .button = on_button, .fault = on_fault};
    p->backend = (struct backend){.ops = backend_lookup(o->backend), .opts = o,
                                  .adc = &p->adc, .button = &p->button};
    perr_clear(&e);
    if (p->backend.ops == NULL) {
        perr_set_path(&e, "bad_backend", o->backend ? o->backend : "", 0);
        send_x(p, &x, encode_fatal(&x, &e));
        free(p);
        return 2;
    }
    if (p->backend.ops->open(&p->backend, clock_ms(), &e) != 0) {
        send_x(p, &x, encode_fatal(&x, &e));
        free(p);
        return 2;
    }
    send_x(p, &x, encode_hello(&x, p->backend.ops->name));
    if (e.reason != NULL)
        on_fault(p, &e);

    while (!p->out_broken && !stop_signal) {
        struct pollfd fds[3];
        int nfds = 0, be = -1, bt = -1, ready;
        long long now = clock_ms();

        fds[nfds++] = (struct pollfd){.fd = in_fd, .events = POLLIN};
        if (p->backend.ops->fd(&p->backend) >= 0) {
            be = nfds;
            fds[nfds++] = (struct pollfd){.fd = p->backend.ops->fd(&p->backend), .events = POLLIN};
        }
        if (p->button.fd >= 0) {
            bt = nfds;
            fds[nfds++] = (struct pollfd){.fd = p->button.fd, .events = POLLIN};
        }
        ready = poll(fds, (nfds_t)nfds, poll_timeout(p, now));
        if (ready < 0 && errno != EINTR) {
            rc = 1;
            break;
        }
        now = clock_ms();
        run_timers(p, now);
        if (ready > 0 && fds[0].revents) {
            rc = read_input(p, in_fd, now);
            if (rc >= 0)
                break;
            rc = 0;
        }
        if (ready > 0 && bt >= 0 && fds[bt].revents)
            read_button(p, now);
        p->backend.ops->run(&p->backend, ready > 0 && be >= 0 && fds[be].revents != 0, now,
                            &p->sink);
    }
    if (p->out_broken)
        rc = 1;
    go_neutral(p);
    button_close(&p->button);
    p->backend.ops->close(&p->backend);
    free(p);
    return rc;
}
