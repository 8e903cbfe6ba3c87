/* The threshold/hysteresis filter (shared with the PRU firmware) and the
 * host's channel table. */
#include "test.h"

#include "adc.h"

/* Feeds samples, returns how many reports came out and the last value. */
static int feed(struct adc_channel *c, const uint16_t *raw, int n, uint16_t *last)
{
    int reports = 0;
    for (int i = 0; i < n; i++) {
        uint16_t v;
        if (adc_filter_sample(c, raw[i], &v)) {
            reports++;
            *last = v;
        }
    }
    return reports;
}

static void hysteresis_is_pure_and_holds_inside_band(void)
{
    CHECK_LL(adc_hysteresis(-1, 2500, 2000, 1500), 1);
    CHECK_LL(adc_hysteresis(-1, 1000, 2000, 1500), 0);
    CHECK_LL(adc_hysteresis(-1, 1700, 2000, 1500), 0);   /* no history, in band: 0 */
    CHECK_LL(adc_hysteresis(1, 1700, 2000, 1500), 1);    /* in band: holds */
    CHECK_LL(adc_hysteresis(0, 1999, 2000, 1500), 0);
    CHECK_LL(adc_hysteresis(0, 2000, 2000, 1500), 1);    /* high is inclusive */
    CHECK_LL(adc_hysteresis(1, 1501, 2000, 1500), 1);
    CHECK_LL(adc_hysteresis(1, 1500, 2000, 1500), 0);    /* low is inclusive */
}

static void one_event_per_crossing_none_for_noise(void)
{
    struct adc_channel c;
    uint16_t last = 99;
    /* first sample is reported; then noise in the band, a crossing up with
     * noise around high, noise in the band, a crossing down. */
    const uint16_t start[] = {1000};
    const uint16_t noise_low[] = {1400, 1600, 1550, 1999, 1700, 1501};
    const uint16_t up[] = {2000, 1990, 2100, 1600, 1999, 2050};
    const uint16_t down[] = {1500, 1510, 1999, 1400, 1000};

    CHECK(adc_filter_configure(&c, ADC_THRESHOLD, 2000, 1500));
    CHECK_LL(feed(&c, start, 1, &last), 1);
    CHECK_LL(last, 0);
    CHECK_LL(feed(&c, noise_low, 6, &last), 0);
    CHECK_LL(feed(&c, up, 6, &last), 1);
    CHECK_LL(last, 1);
    CHECK_LL(feed(&c, down, 5, &last), 1);
    CHECK_LL(last, 0);
}

static void threshold_oscillation_gives_alternating_events(void)
{
    struct adc_channel c;
    uint16_t v = 0;
    int reports = 0, expect = 0;

    CHECK(adc_filter_configure(&c, ADC_THRESHOLD, 3000, 1000));
    for (int i = 0; i < 10; i++) {
        uint16_t raw = i % 2 ? 3500 : 500;
        if (adc_filter_sample(&c, raw, &v)) {
            reports++;
            CHECK_LL(v, i % 2);
        }
        expect++;
    }
    CHECK_LL(reports, expect);
}

static void analog_reports_raw_on_change_only(void)
{
    struct adc_channel c;
    uint16_t last = 0;
    const uint16_t raw[] = {10, 10, 11, 11, 11, 4095, 0, 0};

    CHECK(adc_filter_configure(&c, ADC_ANALOG, 0, 0));
    CHECK_LL(feed(&c, raw, 8, &last), 4);  /* 10, 11, 4095, 0 */
    CHECK_LL(last, 0);
}

static void reconfiguring_reports_the_next_sample_again(void)
{
    struct adc_channel c;
    uint16_t v = 0;

    CHECK(adc_filter_configure(&c, ADC_THRESHOLD, 2000, 1500));
    CHECK(adc_filter_sample(&c, 2500, &v));
    CHECK(!adc_filter_sample(&c, 2600, &v));
    CHECK(adc_filter_configure(&c, ADC_THRESHOLD, 2000, 1500));
    CHECK(adc_filter_sample(&c, 2600, &v));
    CHECK_LL(v, 1);
}

static void filter_refuses_bad_thresholds(void)
{
    struct adc_channel c;
    uint16_t v;

    CHECK(!adc_filter_configure(&c, ADC_THRESHOLD, 1500, 1500));
    CHECK(!adc_filter_configure(&c, ADC_THRESHOLD, 1000, 1500));
    CHECK(!adc_filter_configure(&c, ADC_THRESHOLD, 5000, 1500));
    CHECK(!adc_filter_configure(&c, 9, 0, 0));
    CHECK_LL(c.mode, ADC_OFF);
    CHECK(!adc_filter_sample(&c, 100, &v));   /* off: silent */
}

static void bank_validates_whole_set_before_applying(void)
{
    struct adc_bank b;
    struct perr e;
    struct adc_config ok[2] = {{.channel = 0, .mode = ADC_ANALOG},
                               {.channel = 3, .mode = ADC_THRESHOLD, .high = 2000, .low = 100}};
    struct adc_config dup[2] = {{.channel = 1, .mode = ADC_ANALOG}, {.channel = 1, .mode = ADC_ANALOG}};
    struct adc_config range[1] = {{.channel = 8, .mode = ADC_ANALOG}};
    struct adc_config thr[2] = {{.channel = 5, .mode = ADC_ANALOG},
                                {.channel = 2, .mode = ADC_THRESHOLD, .high = 100, .low = 200}};

    adc_init(&b);
    perr_clear(&e);
    CHECK_LL(adc_configure(&b, ok, 2, &e), 0);
    CHECK(adc_configured(&b, 0) && adc_configured(&b, 3) && !adc_configured(&b, 1));
    CHECK_LL(adc_configure(&b, dup, 2, &e), -1);
    CHECK_STR(e.reason, "duplicate_channel");
    CHECK_LL(e.num, 1);
    CHECK_LL(adc_configure(&b, range, 1, &e), -1);
    CHECK_STR(e.reason, "bad_channel");
    CHECK_LL(adc_configure(&b, thr, 2, &e), -1);
    CHECK_STR(e.reason, "bad_threshold");
    CHECK_LL(e.num, 2);
    /* refused sets changed nothing */
    CHECK(adc_configured(&b, 0) && adc_configured(&b, 3) && !adc_configured(&b, 5));
    CHECK_LL(adc_configure(&b, NULL, 0, &e), 0);
    CHECK(!adc_configured(&b, 0));
}

const struct test_case adc_tests[] = {
    TEST_CASE(hysteresis_is_pure_and_holds_inside_band),
    TEST_CASE(one_event_per_crossing_none_for_noise),
    TEST_CASE(threshold_oscillation_gives_alternating_events),
    TEST_CASE(analog_reports_raw_on_change_only),
    TEST_CASE(reconfiguring_reports_the_next_sample_again),
    TEST_CASE(filter_refuses_bad_thresholds),
    TEST_CASE(bank_validates_whole_set_before_applying),
    {NULL, NULL},
};
