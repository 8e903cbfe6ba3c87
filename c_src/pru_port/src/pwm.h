/*
 * Servo PWM through the kernel's sysfs PWM interface:
 *   <root>/class/pwm/pwmchipN/export
 *   <root>/class/pwm/pwmchipN/pwmM/{period,duty_cycle,enable}
 * (or pwm-N:M/, the name newer BeagleBone kernels give the channel).
 *
 * A continuous-rotation servo turns a velocity in -100..100 into a pulse
 * width around a calibrated neutral pulse (which stops it): this mapping is
 * the pure function pwm_pulse_ns(); the rest writes files.
 */
#ifndef PWM_H
#define PWM_H

#include <stdbool.h>

#include "error.h"

#define MAX_SERVOS 8
#define SERVO_ID_MAX 64           /* bytes, including the NUL */
#define VELOCITY_MAX 100

/* A servo's configuration as requested (range-checked by pwm_configure). */
struct servo_config {
    char id[SERVO_ID_MAX];
    long long pwmchip;
    long long channel;
    long long period_ns;
    long long neutral_ns;         /* the pulse that stops the servo */
    long long span_ns;            /* pulse offset at full speed */
    bool reversed;                /* mounted mirrored: positive velocity shortens the pulse */
};

struct servo_velocity {
    char id[SERVO_ID_MAX];
    long long velocity;
};

struct servo {
    struct servo_config cfg;
    char dir[128];                 /* sysfs directory of the channel, relative to root */
    long long pulse_ns;           /* last duty_cycle written */
};

struct pwm_bank {
    const char *root;
    int n;
    struct servo s[MAX_SERVOS];
    bool enabled;
};

/* Pulse width for a velocity, rounded to the nearest ns; velocity must be
 * within -VELOCITY_MAX..VELOCITY_MAX. */
long long pwm_pulse_ns(const struct servo_config *c, long long velocity);
/* Checks a calibration; on failure names the servo in *e. */
bool pwm_config_valid(const struct servo_config *c, struct perr *e);

void pwm_init(struct pwm_bank *b, const char *sysfs_root);
/* Replaces the servo set: validates all, then exports each channel, writes
 * its period, puts it at neutral and applies the bank's enable state.
 * Servos dropped from the set are disabled. */
int pwm_configure(struct pwm_bank *b, const struct servo_config *cfg, int n,
                  struct perr *e);
/* Sets velocities; all are validated before any is written. */
int pwm_set(struct pwm_bank *b, const struct servo_velocity *v, int n, struct perr *e);
/* Every servo to its neutral pulse; keeps going past errors, reports the first. */
int pwm_neutral(struct pwm_bank *b, struct perr *e);
int pwm_enable(struct pwm_bank *b, bool on, struct perr *e);

#endif
