/*
 * Servo watchdog, as a pure timer over a millisecond clock the caller
 * passes in: if no servo command arrives for period_ms, it expires once,
 * and stays quiet until the next command re-arms it. period 0 disables it.
 */
#ifndef WATCHDOG_H
#define WATCHDOG_H

#include <stdbool.h>

struct watchdog {
    long long period_ms;    /* 0: disabled */
    long long deadline_ms;  /* meaningful while armed */
    bool armed;
};

void watchdog_init(struct watchdog *w, long long period_ms);
/* A servo command arrived at now_ms: (re)arm. */
void watchdog_kick(struct watchdog *w, long long now_ms);
/* Changes the period; an armed watchdog counts the new period from now_ms. */
void watchdog_set_period(struct watchdog *w, long long period_ms, long long now_ms);
/* True exactly once per expiry; disarms until the next kick. */
bool watchdog_expired(struct watchdog *w, long long now_ms);
/* Milliseconds until expiry (>= 0), or -1 when nothing is pending: the
 * poll() timeout contribution. */
long long watchdog_timeout(const struct watchdog *w, long long now_ms);

#endif
