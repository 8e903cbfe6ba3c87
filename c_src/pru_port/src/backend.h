/*
 * The seam between the port program and where its inputs come from.
 *
 *   pru  the board: the PRU firmware polls the ADC and posts changes over an
 *        rpmsg character device (after remoteproc loads it); the button is a
 *        libgpiod line.
 *   sim  no hardware: ADC samples come from a script file and from sim_adc
 *        requests, the button from sim_button requests; both run through
 *        the same filter and debounce code as the board.
 *
 * Servo PWM is not behind this seam: it always goes to sysfs, whose root
 * is configurable, so tests run the real PWM code against a fake tree.
 */
#ifndef BACKEND_H
#define BACKEND_H

#include <stdbool.h>

#include "adc.h"
#include "error.h"
#include "gpio.h"

struct port_opts {
    const char *backend;          /* "sim" | "pru" */
    const char *sysfs_root;       /* "/sys" */
    const char *gpiochip;         /* "/dev/gpiochip0" */
    long long watchdog_ms;        /* 0: off until configured */
    const char *sim_script;       /* sim: NULL or a script file */
    const char *remoteproc;       /* pru: remoteproc dir, relative to sysfs_root */
    const char *firmware;         /* pru: NULL leaves the PRU as it is */
    const char *rpmsg_dev;        /* pru: "/dev/rpmsg_pru30" */
    long long rpmsg_wait_ms;      /* pru: how long the device may take to appear */
};

/* Where a backend delivers what it observed. */
struct backend_sink {
    void *ctx;
    void (*adc)(void *ctx, unsigned channel, unsigned value, long long now_ms);
    void (*button)(void *ctx, enum button_edge edge, long long now_ms);
    void (*fault)(void *ctx, const struct perr *e);
};

struct backend;

struct backend_ops {
    const char *name;
    /* -1: cannot run at all (*e says why). 0 with e->reason set: runs degraded. */
    int (*open)(struct backend *b, long long now_ms, struct perr *e);
    void (*close)(struct backend *b);
    int (*fd)(const struct backend *b);                             /* -1: none */
    long long (*timeout)(const struct backend *b, long long now_ms); /* -1: none */
    /* Each loop turn; readable tells whether fd() polled readable. */
    void (*run)(struct backend *b, bool readable, long long now_ms,
                const struct backend_sink *s);
    /* b->adc was just replaced by a validated table. */
    int (*configure_adc)(struct backend *b, struct perr *e);
    int (*configure_button)(struct backend *b, long long line, bool active_low,
                            long long debounce_ms, struct perr *e);
    int (*sim_adc)(struct backend *b, long long channel, long long value, long long now_ms,
                   const struct backend_sink *s, struct perr *e);
    int (*sim_button)(struct backend *b, long long level, long long now_ms,
                      const struct backend_sink *s, struct perr *e);
};

struct backend {
    const struct backend_ops *ops;
    const struct port_opts *opts;
    struct adc_bank *adc;         /* owned by the port */
    struct button *button;        /* owned by the port */
    void *impl;
};

extern const struct backend_ops backend_sim_ops;
extern const struct backend_ops backend_pru_ops;

/* The ops named name, or NULL. */
const struct backend_ops *backend_lookup(const char *name);

#endif
