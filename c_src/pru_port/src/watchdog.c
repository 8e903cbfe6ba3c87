#include "watchdog.h"

void watchdog_init(struct watchdog *w, long long period_ms)
{
    w->period_ms = period_ms > 0 ? period_ms : 0;
    w->deadline_ms = 0;
    w->armed = false;
}

void watchdog_kick(struct watchdog *w, long long now_ms)
{
    if (w->period_ms == 0)
        return;
    w->armed = true;
    w->deadline_ms = now_ms + w->period_ms;
}

void watchdog_set_period(struct watchdog *w, long long period_ms, long long now_ms)
{
    bool was_armed = w->armed;

    watchdog_init(w, period_ms);
    if (was_armed)
        watchdog_kick(w, now_ms);
}

bool watchdog_expired(struct watchdog *w, long long now_ms)
{
    if (!w->armed || now_ms < w->deadline_ms)
        return false;
    w->armed = false;
    return true;
}

long long watchdog_timeout(const struct watchdog *w, long long now_ms)
{
    if (!w->armed)
        return -1;
    return w->deadline_ms > now_ms ? w->deadline_ms - now_ms : 0;
}
