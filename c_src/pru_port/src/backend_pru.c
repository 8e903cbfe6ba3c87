/*
 * The pru backend: remoteproc loads the firmware (when asked), the firmware
 * filters the ADC (adc_filter.c, on the PRU) and posts changes over the
 * rpmsg character device; the button is a libgpiod line. See backend.h.
 */
#include "backend.h"

#include <errno.h>
#include <fcntl.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <unistd.h>

#include "pru_msg.h"
#include "sysfs.h"

struct pru {
    int fd;                               /* rpmsg device, -1 when absent */
    uint8_t rx[PRU_MSG_SIZE * 64];
    size_t rx_len;
};

/* Loads and (re)starts the firmware: remoteproc refuses a firmware change
 * while running, so a running PRU is stopped first. */
static int remoteproc_start(const struct port_opts *o, struct perr *e)
{
    char rel[256], state[32];

    snprintf(rel, sizeof rel, "%s/state", o->remoteproc);
    if (sysfs_read(o->sysfs_root, rel, state, sizeof state, e) != 0)
        return -1;
    if (strcmp(state, "running") == 0 && sysfs_write(o->sysfs_root, rel, "stop", e) != 0)
        return -1;
    snprintf(rel, sizeof rel, "%s/firmware", o->remoteproc);
    if (sysfs_write(o->sysfs_root, rel, o->firmware, e) != 0)
        return -1;
    snprintf(rel, sizeof rel, "%s/state", o->remoteproc);
    return sysfs_write(o->sysfs_root, rel, "start", e);
}

static int send_msg(struct pru *p, const struct pru_msg *m, const char *dev, struct perr *e)
{
    uint8_t out[PRU_MSG_SIZE];
    ssize_t w;

    if (p->fd < 0) {
        perr_set_path(e, "rpmsg", dev, ENODEV);
        return -1;
    }
    pru_msg_pack(m, out);
    do {
        w = write(p->fd, out, sizeof out);
    } while (w < 0 && errno == EINTR);
    if (w != (ssize_t)sizeof out) {
        perr_set_path(e, "rpmsg", dev, w < 0 ? errno : EIO);
        return -1;
    }
    return 0;
}

static int pru_open(struct backend *b, long long now_ms, struct perr *e)
{
    const struct port_opts *o = b->opts;
    struct pru *p = calloc(1, sizeof *p);
    struct pru_msg hello = {.type = PRU_MSG_HELLO};
    long long waited = 0;

    (void)now_ms;
    if (p == NULL) {
        perr_set(e, "enomem");
        return -1;
    }
    p->fd = -1;
    b->impl = p;
    if (o->firmware != NULL && remoteproc_start(o, e) != 0)
        return 0;                          /* degraded: servos still work */
    /* the device node appears only once the firmware has announced itself */
    for (;;) {
        p->fd = open(o->rpmsg_dev, O_RDWR | O_NONBLOCK | O_CLOEXEC);
        if (p->fd >= 0 || waited >= o->rpmsg_wait_ms)
            break;
        nanosleep(&(struct timespec){.tv_sec = 0, .tv_nsec = 20 * 1000000L}, NULL);
        waited += 20;
    }
    if (p->fd < 0) {
        perr_set_path(e, "rpmsg", o->rpmsg_dev, errno);
        return 0;
    }
    if (send_msg(p, &hello, o->rpmsg_dev, e) != 0) {
        close(p->fd);
        p->fd = -1;
    }
    return 0;
}

static void pru_close(struct backend *b)
{
    struct pru *p = b->impl;
    if (p != NULL && p->fd >= 0)
        close(p->fd);
    free(p);
    b->impl = NULL;
}

static int pru_fd(const struct backend *b)
{
    const struct pru *p = b->impl;
    return p->fd;
}

static long long pru_timeout(const struct backend *b, long long now_ms)
{
    (void)b;
    (void)now_ms;
    return -1;
}

static void pru_run(struct backend *b, bool readable, long long now_ms,
                    const struct backend_sink *k)
{
    struct pru *p = b->impl;
    ssize_t n;
    size_t off = 0;

    if (!readable || p->fd < 0)
        return;
    n = read(p->fd, p->rx + p->rx_len, sizeof p->rx - p->rx_len);
    if (n <= 0) {
        struct perr e;
        if (n < 0 && (errno == EAGAIN || errno == EINTR))
            return;
        perr_set_path(&e, "rpmsg", b->opts->rpmsg_dev, n < 0 ? errno : EIO);
        k->fault(k->ctx, &e);
        close(p->fd);
        p->fd = -1;
        return;
    }
    p->rx_len += (size_t)n;
    for (; p->rx_len - off >= PRU_MSG_SIZE; off += PRU_MSG_SIZE) {
        struct pru_msg m;
        pru_msg_unpack(p->rx + off, &m);
        /* The firmware filtered already; the host only checks it asked for it. */
        if (m.type == PRU_MSG_ADC_CHANGE && adc_configured(b->adc, m.channel))
            k->adc(k->ctx, m.channel, m.a, now_ms);
    }
    memmove(p->rx, p->rx + off, p->rx_len - off);
    p->rx_len -= off;
}

static int pru_configure_adc(struct backend *b, struct perr *e)
{
    struct pru *p = b->impl;

    /* Every channel is sent, so the firmware's table is replaced whole. */
    for (unsigned ch = 0; ch < ADC_CHANNELS; ch++) {
        const struct adc_channel *c = &b->adc->ch[ch];
        struct pru_msg m = {.type = PRU_MSG_CONFIG, .channel = (uint8_t)ch,
                            .mode = c->mode, .a = c->high, .b = c->low};
        if (send_msg(p, &m, b->opts->rpmsg_dev, e) != 0)
            return -1;
    }
    return 0;
}

static int pru_configure_button(struct backend *b, long long line, bool active_low,
                                long long debounce_ms, struct perr *e)
{
    return button_open_gpiod(b->button, b->opts->gpiochip, line, active_low, debounce_ms, e);
}

static int pru_sim_adc(struct backend *b, long long channel, long long value, long long now_ms,
                       const struct backend_sink *k, struct perr *e)
{
    (void)b;
    (void)channel;
    (void)value;
    (void)now_ms;
    (void)k;
    perr_set_atom(e, "not_simulated", "pru");
    return -1;
}

static int pru_sim_button(struct backend *b, long long level, long long now_ms,
                          const struct backend_sink *k, struct perr *e)
{
    return pru_sim_adc(b, 0, level, now_ms, k, e);
}

const struct backend_ops backend_pru_ops = {
    .name = "pru",
    .open = pru_open,
    .close = pru_close,
    .fd = pru_fd,
    .timeout = pru_timeout,
    .run = pru_run,
    .configure_adc = pru_configure_adc,
    .configure_button = pru_configure_button,
    .sim_adc = pru_sim_adc,
    .sim_button = pru_sim_button,
};
