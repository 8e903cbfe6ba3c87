/* The sim backend: see backend.h and backend_sim.h. */
#include "backend.h"
#include "backend_sim.h"

#include <errno.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

struct sim {
    struct sim_step *steps;
    int n;
    int next;
    long long next_at_ms;
};

int sim_script_load(const char *path, struct sim_step **steps, int *n, struct perr *e)
{
    FILE *f = fopen(path, "r");
    char line[256];
    int cap = 0, lineno = 0;

    *steps = NULL;
    *n = 0;
    if (f == NULL) {
        perr_set_path(e, "sim_script", path, errno);
        return -1;
    }
    while (fgets(line, sizeof line, f) != NULL) {
        struct sim_step s;
        char what[16], extra[2];
        char *p = line;

        lineno++;
        while (*p == ' ' || *p == '\t')
            p++;
        if (*p == '#' || *p == '\n' || *p == '\r' || *p == '\0')
            continue;
        if (sscanf(p, "%lld %15s %lld %1s", &s.after_ms, what, &s.value, extra) != 3 ||
            s.after_ms < 0) {
            char where[PATH_MAX];
            snprintf(where, sizeof where, "%s:%d", path, lineno);
            perr_set_path(e, "sim_script", where, 0);
            free(*steps);
            *steps = NULL;
            *n = 0;
            fclose(f);
            return -1;
        }
        if (strcmp(what, "button") == 0) {
            s.kind = SIM_STEP_BUTTON;
            s.channel = 0;
        } else {
            char *end;
            s.kind = SIM_STEP_ADC;
            s.channel = strtoll(what, &end, 10);
            if (*end != '\0')
                s.channel = -1;   /* rejected when the step runs, like a bad sim_adc */
        }
        if (*n == cap) {
            struct sim_step *grown;
            cap = cap ? cap * 2 : 16;
            grown = realloc(*steps, (size_t)cap * sizeof **steps);
            if (grown == NULL) {
                perr_set_path(e, "sim_script", path, ENOMEM);
                free(*steps);
                *steps = NULL;
                *n = 0;
                fclose(f);
                return -1;
            }
            *steps = grown;
        }
        (*steps)[(*n)++] = s;
    }
    fclose(f);
    return 0;
}

static int sim_open(struct backend *b, long long now_ms, struct perr *e)
{
    struct sim *s = calloc(1, sizeof *s);

    if (s == NULL) {
        perr_set(e, "enomem");
        return -1;
    }
    if (b->opts->sim_script != NULL &&
        sim_script_load(b->opts->sim_script, &s->steps, &s->n, e) != 0) {
        free(s);
        return -1;
    }
    if (s->n > 0)
        s->next_at_ms = now_ms + s->steps[0].after_ms;
    b->impl = s;
    return 0;
}

static void sim_close(struct backend *b)
{
    struct sim *s = b->impl;
    if (s != NULL)
        free(s->steps);
    free(s);
    b->impl = NULL;
}

static int sim_fd(const struct backend *b)
{
    (void)b;
    return -1;
}

static long long sim_timeout(const struct backend *b, long long now_ms)
{
    const struct sim *s = b->impl;
    if (s->next >= s->n)
        return -1;
    return s->next_at_ms > now_ms ? s->next_at_ms - now_ms : 0;
}

static int feed_adc(struct backend *b, long long channel, long long value, long long now_ms,
                    const struct backend_sink *k, struct perr *e)
{
    uint16_t out;

    if (!adc_configured(b->adc, channel)) {
        perr_set_int(e, "unconfigured_channel", channel);
        return -1;
    }
    if (value < 0 || value > (long long)ADC_MAX_RAW) {
        perr_set_int(e, "bad_adc_value", value);
        return -1;
    }
    if (adc_sample(b->adc, (unsigned)channel, (uint16_t)value, &out))
        k->adc(k->ctx, (unsigned)channel, out, now_ms);
    return 0;
}

static int feed_button(struct backend *b, long long level, long long now_ms,
                       const struct backend_sink *k, struct perr *e)
{
    enum button_edge edge;

    if (!b->button->configured) {
        perr_set(e, "button_not_configured");
        return -1;
    }
    if (level != 0 && level != 1) {
        perr_set_int(e, "bad_level", level);
        return -1;
    }
    edge = button_input(b->button, (int)level, now_ms);
    if (edge != BUTTON_NONE)
        k->button(k->ctx, edge, now_ms);
    return 0;
}

static void sim_run(struct backend *b, bool readable, long long now_ms,
                    const struct backend_sink *k)
{
    struct sim *s = b->impl;

    (void)readable;
    while (s->next < s->n && now_ms >= s->next_at_ms) {
        const struct sim_step *st = &s->steps[s->next];
        struct perr ignored;

        /* A script may sample channels the controller has not configured
         * (yet): those samples are dropped, as the board would drop them. */
        perr_clear(&ignored);
        if (st->kind == SIM_STEP_ADC)
            (void)feed_adc(b, st->channel, st->value, now_ms, k, &ignored);
        else
            (void)feed_button(b, st->value, now_ms, k, &ignored);
        s->next++;
        if (s->next < s->n)
            s->next_at_ms += s->steps[s->next].after_ms;
    }
}

static int sim_configure_adc(struct backend *b, struct perr *e)
{
    (void)b;
    (void)e;
    return 0;
}

static int sim_configure_button(struct backend *b, long long line, bool active_low,
                                long long debounce_ms, struct perr *e)
{
    (void)line;
    (void)e;
    button_close(b->button);
    /* the simulated line starts released */
    button_configure(b->button, active_low, debounce_ms, active_low ? 1 : 0);
    return 0;
}

static int sim_adc(struct backend *b, long long channel, long long value, long long now_ms,
                   const struct backend_sink *k, struct perr *e)
{
    return feed_adc(b, channel, value, now_ms, k, e);
}

static int sim_button(struct backend *b, long long level, long long now_ms,
                      const struct backend_sink *k, struct perr *e)
{
    return feed_button(b, level, now_ms, k, e);
}

const struct backend_ops backend_sim_ops = {
    .name = "sim",
    .open = sim_open,
    .close = sim_close,
    .fd = sim_fd,
    .timeout = sim_timeout,
    .run = sim_run,
    .configure_adc = sim_configure_adc,
    .configure_button = sim_configure_button,
    .sim_adc = sim_adc,
    .sim_button = sim_button,
};
