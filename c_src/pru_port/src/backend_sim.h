/*
 * The sim backend's script: one step per line,
 *     AFTER_MS CHANNEL VALUE      an ADC sample (raw, 0..4095)
 *     AFTER_MS button LEVEL       the button line's physical level (0/1)
 * AFTER_MS counts from the previous step (the first from start-up);
 * blank lines and lines starting with # are ignored.
 */
#ifndef BACKEND_SIM_H
#define BACKEND_SIM_H

#include "error.h"

enum sim_step_kind { SIM_STEP_ADC, SIM_STEP_BUTTON };

struct sim_step {
    long long after_ms;
    enum sim_step_kind kind;
    long long channel;
    long long value;
};

/* Parses a script; *steps is malloc'ed (free it). On error *e is
 * {sim_script, "path:line"}. */
int sim_script_load(const char *path, struct sim_step **steps, int *n, struct perr *e);

#endif
