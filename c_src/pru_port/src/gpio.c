#include "gpio.h"

#include <errno.h>
#include <gpiod.h>
#include <string.h>

#define CONSUMER "toroco-pru-port"

void button_init(struct button *b)
{
    memset(b, 0, sizeof *b);
    b->pending = -1;
    b->fd = -1;
}

static int logical(const struct button *b, int physical)
{
    return (physical != 0) != b->active_low ? BUTTON_PRESSED : BUTTON_RELEASED;
}

void button_configure(struct button *b, bool active_low, long long debounce_ms,
                      int physical_level)
{
    b->configured = true;
    b->active_low = active_low;
    b->debounce_ms = debounce_ms > 0 ? debounce_ms : 0;
    b->reported = logical(b, physical_level);
    b->pending = -1;
}

enum button_edge button_input(struct button *b, int physical_level, long long now_ms)
{
    int state;

    if (!b->configured)
        return BUTTON_NONE;
    state = logical(b, physical_level);
    if (b->debounce_ms > 0) {
        /* every bounce restarts the wait; only a level that holds counts */
        b->pending = state;
        b->pending_since = now_ms;
        return BUTTON_NONE;
    }
    if (state == b->reported)
        return BUTTON_NONE;
    b->reported = state;
    return (enum button_edge)state;
}

enum button_edge button_settle(struct button *b, long long now_ms)
{
    int state = b->pending;

    if (state < 0 || now_ms - b->pending_since < b->debounce_ms)
        return BUTTON_NONE;
    b->pending = -1;
    if (state == b->reported)
        return BUTTON_NONE;
    b->reported = state;
    return (enum button_edge)state;
}

long long button_timeout(const struct button *b, long long now_ms)
{
    long long left;

    if (b->pending < 0)
        return -1;
    left = b->pending_since + b->debounce_ms - now_ms;
    return left > 0 ? left : 0;
}

int button_open_gpiod(struct button *b, const char *chip_path, long long line,
                      bool active_low, long long debounce_ms, struct perr *e)
{
    int value;

    button_close(b);
    if (line < 0 || line > 1023) {
        perr_set_int(e, "bad_gpio_line", line);
        return -1;
    }
    b->chip = gpiod_chip_open(chip_path);
    if (b->chip == NULL) {
        perr_set_path(e, "gpiochip", chip_path, errno ? errno : ENODEV);
        return -1;
    }
    b->line = gpiod_chip_get_line(b->chip, (unsigned)line);
    if (b->line == NULL ||
        gpiod_line_request_both_edges_events(b->line, CONSUMER) != 0 ||
        (value = gpiod_line_get_value(b->line)) < 0 ||
        (b->fd = gpiod_line_event_get_fd(b->line)) < 0) {
        int err = errno ? errno : EIO;
        perr_set_int(e, "gpio_line", line);
        e->errnum = err;
        button_close(b);
        return -1;
    }
    button_configure(b, active_low, debounce_ms, value);
    return 0;
}

enum button_edge button_read_gpiod(struct button *b, long long now_ms, struct perr *e)
{
    struct gpiod_line_event ev;

    if (b->line == NULL)
        return BUTTON_NONE;
    if (gpiod_line_event_read(b->line, &ev) != 0) {
        perr_set_path(e, "gpio_read", gpiod_chip_name(b->chip), errno ? errno : EIO);
        return BUTTON_NONE;
    }
    return button_input(b, ev.event_type == GPIOD_LINE_EVENT_RISING_EDGE ? 1 : 0, now_ms);
}

void button_close(struct button *b)
{
    if (b->line != NULL)
        gpiod_line_release(b->line);
    if (b->chip != NULL)
        gpiod_chip_close(b->chip);
    button_init(b);
}
