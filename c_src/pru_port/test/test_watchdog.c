/* The servo watchdog timer. */
#include "test.h"

#include "watchdog.h"

static void expires_once_after_silence(void)
{
    struct watchdog w;

    watchdog_init(&w, 100);
    CHECK(!watchdog_expired(&w, 1000000));    /* never kicked: nothing to guard */
    CHECK_LL(watchdog_timeout(&w, 0), -1);
    watchdog_kick(&w, 1000);
    CHECK_LL(watchdog_timeout(&w, 1040), 60);
    CHECK(!watchdog_expired(&w, 1099));
    CHECK(watchdog_expired(&w, 1100));
    CHECK(!watchdog_expired(&w, 1101));       /* once per silence */
    CHECK(!watchdog_expired(&w, 5000));
    CHECK_LL(watchdog_timeout(&w, 5000), -1);
}

static void kicks_push_the_deadline(void)
{
    struct watchdog w;

    watchdog_init(&w, 100);
    for (long long t = 0; t < 1000; t += 50) {
        watchdog_kick(&w, t);
        CHECK(!watchdog_expired(&w, t + 99));
    }
    CHECK(watchdog_expired(&w, 1050));
    CHECK_LL(watchdog_timeout(&w, 2000), -1);
    watchdog_kick(&w, 2000);
    CHECK_LL(watchdog_timeout(&w, 2500), 0);  /* overdue: poll must not wait */
}

static void disabled_and_reconfigured(void)
{
    struct watchdog w;

    watchdog_init(&w, 0);
    watchdog_kick(&w, 0);
    CHECK(!watchdog_expired(&w, 1000000));
    watchdog_init(&w, -5);
    CHECK_LL(w.period_ms, 0);
    watchdog_init(&w, 100);
    watchdog_kick(&w, 0);
    watchdog_set_period(&w, 500, 50);         /* armed: counts anew from now */
    CHECK(!watchdog_expired(&w, 500));
    CHECK(watchdog_expired(&w, 550));
    watchdog_set_period(&w, 0, 600);
    CHECK_LL(watchdog_timeout(&w, 600), -1);
}

const struct test_case watchdog_tests[] = {
    TEST_CASE(expires_once_after_silence),
    TEST_CASE(kicks_push_the_deadline),
    TEST_CASE(disabled_and_reconfigured),
    {NULL, NULL},
};
