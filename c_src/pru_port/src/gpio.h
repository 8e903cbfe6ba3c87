/*
 * The button: a GPIO line read through libgpiod (v1 API) from a
 * configurable gpiochip, or a simulated line fed by the sim backend.
 * Polarity and debouncing are plain functions of (level, time) so that
 * both kinds of line share them and tests can drive them.
 */
#ifndef GPIO_H
#define GPIO_H

#include <stdbool.h>

#include "error.h"

struct gpiod_chip;
struct gpiod_line;

enum button_edge { BUTTON_NONE = -1, BUTTON_RELEASED = 0, BUTTON_PRESSED = 1 };

struct button {
    bool configured;
    bool active_low;              /* pressed pulls the line low */
    long long debounce_ms;        /* 0: every edge counts */
    int reported;                 /* the last state reported (or the initial one) */
    int pending;                  /* -1, or the state waiting out the debounce */
    long long pending_since;
    struct gpiod_chip *chip;      /* NULL for a simulated line */
    struct gpiod_line *line;
    int fd;                       /* line event fd to poll, -1 if none */
};

void button_init(struct button *b);
/* Starts tracking a line whose current physical level is known. */
void button_configure(struct button *b, bool active_low, long long debounce_ms,
                      int physical_level);
/* A physical level (0/1) seen at now: the edge to report now, if any. */
enum button_edge button_input(struct button *b, int physical_level, long long now_ms);
/* An edge whose debounce wait is over, if any. */
enum button_edge button_settle(struct button *b, long long now_ms);
/* ms until button_settle has something to say, or -1. */
long long button_timeout(const struct button *b, long long now_ms);

/* Requests both-edge events on line of the gpiochip at chip_path. On
 * failure *e names the chip path ({gpiochip, Path, Errno}) or the line. */
int button_open_gpiod(struct button *b, const char *chip_path, long long line,
                      bool active_low, long long debounce_ms, struct perr *e);
/* Reads one pending line event (the fd polled readable) and feeds it. */
enum button_edge button_read_gpiod(struct button *b, long long now_ms, struct perr *e);
/* Releases the line and the chip; the button is then unconfigured. */
void button_close(struct button *b);

#endif
