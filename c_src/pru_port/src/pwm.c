#include "pwm.h"

#include <stdio.h>
#include <string.h>

#include "sysfs.h"

long long pwm_pulse_ns(const struct servo_config *c, long long velocity)
{
    long long v = c->reversed ? -velocity : velocity;
    long long scaled = v * c->span_ns;
    /* round half away from zero, so +v and -v stay symmetric about neutral */
    long long off = scaled >= 0 ? (scaled + VELOCITY_MAX / 2) / VELOCITY_MAX
                                : -((-scaled + VELOCITY_MAX / 2) / VELOCITY_MAX);
    return c->neutral_ns + off;
}

bool pwm_config_valid(const struct servo_config *c, struct perr *e)
{
    if (c->pwmchip < 0 || c->pwmchip > 255 || c->channel < 0 || c->channel > 255 ||
        c->period_ns <= 0 || c->period_ns > 1000000000LL || c->span_ns < 0 ||
        c->neutral_ns - c->span_ns < 0 || c->neutral_ns + c->span_ns > c->period_ns) {
        perr_set_atom(e, "bad_calibration", c->id);
        return false;
    }
    return true;
}

void pwm_init(struct pwm_bank *b, const char *sysfs_root)
{
    memset(b, 0, sizeof *b);
    b->root = sysfs_root;
}

static struct servo *find(struct pwm_bank *b, const char *id)
{
    for (int i = 0; i < b->n; i++)
        if (strcmp(b->s[i].cfg.id, id) == 0)
            return &b->s[i];
    return NULL;
}

static int write_attr(struct pwm_bank *b, const struct servo *s, const char *attr,
                      long long v, struct perr *e)
{
    char rel[160];
    snprintf(rel, sizeof rel, "%s/%s", s->dir, attr);
    return sysfs_write_ll(b->root, rel, v, e);
}

/* Finds the channel's directory, exporting the channel when it has none. */
static int export_channel(struct pwm_bank *b, struct servo *s, struct perr *e)
{
    char chip[48], rel[128];

    snprintf(chip, sizeof chip, "class/pwm/pwmchip%lld", s->cfg.pwmchip);
    for (int attempt = 0; attempt < 2; attempt++) {
        /* pwmM on most kernels; pwm-N:M on newer BeagleBone ones */
        snprintf(s->dir, sizeof s->dir, "%s/pwm%lld", chip, s->cfg.channel);
        if (sysfs_exists(b->root, s->dir))
            return 0;
        snprintf(s->dir, sizeof s->dir, "%s/pwm-%lld:%lld", chip, s->cfg.pwmchip,
                 s->cfg.channel);
        if (sysfs_exists(b->root, s->dir))
            return 0;
        if (attempt == 0) {
            snprintf(rel, sizeof rel, "%s/export", chip);
            if (sysfs_write_ll(b->root, rel, s->cfg.channel, e) != 0)
                return -1;
        }
    }
    snprintf(rel, sizeof rel, "%s/pwm%lld", chip, s->cfg.channel);
    perr_set_path(e, "pwm_not_exported", rel, 0);
    return -1;
}

static int setup(struct pwm_bank *b, struct servo *s, struct perr *e)
{
    /* duty_cycle may never exceed period: clear it before changing the period */
    if (write_attr(b, s, "duty_cycle", 0, e) != 0 ||
        write_attr(b, s, "period", s->cfg.period_ns, e) != 0 ||
        write_attr(b, s, "duty_cycle", s->cfg.neutral_ns, e) != 0 ||
        write_attr(b, s, "enable", b->enabled ? 1 : 0, e) != 0)
        return -1;
    s->pulse_ns = s->cfg.neutral_ns;
    return 0;
}

int pwm_configure(struct pwm_bank *b, const struct servo_config *cfg, int n,
                  struct perr *e)
{
    struct servo next[MAX_SERVOS];

    if (n < 0 || n > MAX_SERVOS) {
        perr_set_int(e, "too_many_servos", n);
        return -1;
    }
    for (int i = 0; i < n; i++) {
        if (!pwm_config_valid(&cfg[i], e))
            return -1;
        for (int j = 0; j < i; j++) {
            if (strcmp(cfg[i].id, cfg[j].id) == 0) {
                perr_set_atom(e, "duplicate_servo", cfg[i].id);
                return -1;
            }
            if (cfg[i].pwmchip == cfg[j].pwmchip && cfg[i].channel == cfg[j].channel) {
                perr_set_atom(e, "duplicate_pwm_channel", cfg[i].id);
                return -1;
            }
        }
    }
    /* Every channel must exist before any servo changes: a missing chip
     * then refuses the whole set and the servos in use keep running. */
    for (int i = 0; i < n; i++) {
        memset(&next[i], 0, sizeof next[i]);
        next[i].cfg = cfg[i];
        if (export_channel(b, &next[i], e) != 0)
            return -1;
    }
    /* Channels that leave the set stop driving their servo. */
    for (int i = 0; i < b->n; i++) {
        bool kept = false;
        for (int j = 0; j < n; j++)
            kept |= b->s[i].cfg.pwmchip == cfg[j].pwmchip && b->s[i].cfg.channel == cfg[j].channel;
        if (!kept) {
            struct perr ignored;
            perr_clear(&ignored);
            (void)write_attr(b, &b->s[i], "enable", 0, &ignored);
        }
    }
    memcpy(b->s, next, sizeof next[0] * (size_t)n);
    b->n = n;
    for (int i = 0; i < n; i++) {
        if (setup(b, &b->s[i], e) != 0) {
            b->n = i;   /* keep only the servos that are really set up */
            return -1;
        }
    }
    return 0;
}

int pwm_set(struct pwm_bank *b, const struct servo_velocity *v, int n, struct perr *e)
{
    struct servo *targets[MAX_SERVOS];

    for (int i = 0; i < n; i++) {
        targets[i] = find(b, v[i].id);
        if (targets[i] == NULL) {
            perr_set_atom(e, "unknown_servo", v[i].id);
            return -1;
        }
        if (v[i].velocity < -VELOCITY_MAX || v[i].velocity > VELOCITY_MAX) {
            perr_set_atom(e, "bad_velocity", v[i].id);
            return -1;
        }
    }
    for (int i = 0; i < n; i++) {
        long long pulse = pwm_pulse_ns(&targets[i]->cfg, v[i].velocity);
        if (write_attr(b, targets[i], "duty_cycle", pulse, e) != 0)
            return -1;
        targets[i]->pulse_ns = pulse;
    }
    return 0;
}

int pwm_neutral(struct pwm_bank *b, struct perr *e)
{
    int rc = 0;

    for (int i = 0; i < b->n; i++) {
        struct perr mine;
        struct servo *s = &b->s[i];
        perr_clear(&mine);
        if (write_attr(b, s, "duty_cycle", s->cfg.neutral_ns, &mine) != 0) {
            if (rc == 0)
                *e = mine;
            rc = -1;
            continue;
        }
        s->pulse_ns = s->cfg.neutral_ns;
    }
    return rc;
}

int pwm_enable(struct pwm_bank *b, bool on, struct perr *e)
{
    b->enabled = on;
    for (int i = 0; i < b->n; i++)
        if (write_attr(b, &b->s[i], "enable", on ? 1 : 0, e) != 0)
            return -1;
    return 0;
}
