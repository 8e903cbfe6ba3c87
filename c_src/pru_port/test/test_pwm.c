/* Velocity -> pulse mapping, and the sysfs PWM writes against a fake tree. */
#include "test.h"

#include <sys/stat.h>

#include "pwm.h"

static struct servo_config servo(const char *id, int chip, int ch, bool reversed)
{
    struct servo_config c = {.pwmchip = chip, .channel = ch, .period_ns = 20000000,
                             .neutral_ns = 1500000, .span_ns = 500000, .reversed = reversed};
    snprintf(c.id, sizeof c.id, "%s", id);
    return c;
}

static void pulse_width_follows_velocity(void)
{
    struct servo_config c = servo("l", 0, 0, false);
    struct servo_config r = servo("r", 0, 1, true);

    CHECK_LL(pwm_pulse_ns(&c, 0), 1500000);
    CHECK_LL(pwm_pulse_ns(&c, 100), 2000000);
    CHECK_LL(pwm_pulse_ns(&c, -100), 1000000);
    CHECK_LL(pwm_pulse_ns(&c, 50), 1750000);
    CHECK_LL(pwm_pulse_ns(&c, 1), 1505000);
    CHECK_LL(pwm_pulse_ns(&r, 100), 1000000);
    CHECK_LL(pwm_pulse_ns(&r, -100), 2000000);
    CHECK_LL(pwm_pulse_ns(&r, 0), 1500000);
}

static void pulse_rounds_symmetrically(void)
{
    struct servo_config c = servo("l", 0, 0, false);

    c.neutral_ns = 1520000;  /* a calibrated, off-centre neutral */
    c.span_ns = 333;
    for (int v = 1; v <= 100; v++)
        CHECK_LL(pwm_pulse_ns(&c, v) - c.neutral_ns, c.neutral_ns - pwm_pulse_ns(&c, -v));
    CHECK_LL(pwm_pulse_ns(&c, 50), 1520000 + 167);   /* 166.5 rounds away from 0 */
}

static void calibration_is_checked(void)
{
    struct perr e;
    struct servo_config c = servo("bad", 0, 0, false);

    CHECK(pwm_config_valid(&c, &e));
    c.span_ns = 1600000;  /* would need a negative pulse */
    CHECK(!pwm_config_valid(&c, &e));
    CHECK_STR(e.reason, "bad_calibration");
    CHECK_STR(e.text, "bad");
    c = servo("bad", 0, 0, false);
    c.period_ns = 1800000;  /* neutral + span beyond the period */
    CHECK(!pwm_config_valid(&c, &e));
    c = servo("bad", -1, 0, false);
    CHECK(!pwm_config_valid(&c, &e));
}

static void configure_writes_period_then_neutral(void)
{
    const char *root = fixture_tmpdir();
    struct pwm_bank b;
    struct perr e;
    struct servo_config s[2] = {servo("left", 0, 0, false), servo("right", 0, 1, true)};

    fixture_pwm(root, 0, 0, true);
    fixture_pwm(root, 0, 1, true);
    fixture_write(root, "class/pwm/pwmchip0/pwm0/duty_cycle", "1900000\n");
    pwm_init(&b, root);
    perr_clear(&e);
    CHECK_LL(pwm_configure(&b, s, 2, &e), 0);
    CHECK_STR(fixture_read(root, "class/pwm/pwmchip0/pwm0/period"), "20000000");
    CHECK_STR(fixture_read(root, "class/pwm/pwmchip0/pwm0/duty_cycle"), "1500000");
    CHECK_STR(fixture_read(root, "class/pwm/pwmchip0/pwm1/duty_cycle"), "1500000");
    CHECK_STR(fixture_read(root, "class/pwm/pwmchip0/pwm0/enable"), "0");
    /* already exported: export is left alone */
    CHECK_STR(fixture_read(root, "class/pwm/pwmchip0/export"), "");
}

static void set_enable_and_neutral_write_duty_cycle(void)
{
    const char *root = fixture_tmpdir();
    struct pwm_bank b;
    struct perr e;
    struct servo_config s[2] = {servo("left", 0, 0, false), servo("right", 0, 1, true)};
    struct servo_velocity full[2] = {{"left", 100}, {"right", 100}};
    struct servo_velocity back[2] = {{"left", -100}, {"right", -100}};

    fixture_pwm(root, 0, 0, true);
    fixture_pwm(root, 0, 1, true);
    pwm_init(&b, root);
    perr_clear(&e);
    CHECK_LL(pwm_configure(&b, s, 2, &e), 0);
    CHECK_LL(pwm_enable(&b, true, &e), 0);
    CHECK_STR(fixture_read(root, "class/pwm/pwmchip0/pwm0/enable"), "1");
    CHECK_STR(fixture_read(root, "class/pwm/pwmchip0/pwm1/enable"), "1");
    CHECK_LL(pwm_set(&b, full, 2, &e), 0);
    CHECK_STR(fixture_read(root, "class/pwm/pwmchip0/pwm0/duty_cycle"), "2000000");
    CHECK_STR(fixture_read(root, "class/pwm/pwmchip0/pwm1/duty_cycle"), "1000000");
    CHECK_LL(pwm_set(&b, back, 2, &e), 0);
    CHECK_STR(fixture_read(root, "class/pwm/pwmchip0/pwm0/duty_cycle"), "1000000");
    CHECK_STR(fixture_read(root, "class/pwm/pwmchip0/pwm1/duty_cycle"), "2000000");
    CHECK_LL(pwm_neutral(&b, &e), 0);
    CHECK_STR(fixture_read(root, "class/pwm/pwmchip0/pwm0/duty_cycle"), "1500000");
    CHECK_STR(fixture_read(root, "class/pwm/pwmchip0/pwm1/duty_cycle"), "1500000");
    CHECK_LL(pwm_enable(&b, false, &e), 0);
    CHECK_STR(fixture_read(root, "class/pwm/pwmchip0/pwm1/enable"), "0");
}

static void a_refused_set_writes_nothing(void)
{
    const char *root = fixture_tmpdir();
    struct pwm_bank b;
    struct perr e;
    struct servo_config s[1] = {servo("left", 0, 0, false)};
    struct servo_velocity bad[2] = {{"left", 100}, {"right", 10}};
    struct servo_velocity fast[1] = {{"left", 101}};

    fixture_pwm(root, 0, 0, true);
    pwm_init(&b, root);
    perr_clear(&e);
    CHECK_LL(pwm_configure(&b, s, 1, &e), 0);
    CHECK_LL(pwm_set(&b, bad, 2, &e), -1);
    CHECK_STR(e.reason, "unknown_servo");
    CHECK_STR(e.text, "right");
    CHECK_LL(pwm_set(&b, fast, 1, &e), -1);
    CHECK_STR(e.reason, "bad_velocity");
    CHECK_STR(fixture_read(root, "class/pwm/pwmchip0/pwm0/duty_cycle"), "1500000");
}

static void exports_a_missing_channel(void)
{
    const char *root = fixture_tmpdir();
    struct pwm_bank b;
    struct perr e;
    struct servo_config s[1] = {servo("left", 2, 1, false)};

    /* a fake tree cannot grow pwm1/ on export, so the write is all we see
     * and the channel is reported missing, naming its path */
    fixture_pwm(root, 2, 1, false);
    pwm_init(&b, root);
    perr_clear(&e);
    CHECK_LL(pwm_configure(&b, s, 1, &e), -1);
    CHECK_STR(fixture_read(root, "class/pwm/pwmchip2/export"), "1");
    CHECK_STR(e.reason, "pwm_not_exported");
    CHECK_STR(e.text, "class/pwm/pwmchip2/pwm1");
    CHECK_LL(b.n, 0);
}

static void finds_the_pwm_dash_chip_colon_channel_layout(void)
{
    const char *root = fixture_tmpdir();
    struct pwm_bank b;
    struct perr e;
    struct servo_config s[1] = {servo("left", 3, 0, false)};

    fixture_touch(root, "class/pwm/pwmchip3/export");
    fixture_touch(root, "class/pwm/pwmchip3/pwm-3:0/period");
    fixture_touch(root, "class/pwm/pwmchip3/pwm-3:0/duty_cycle");
    fixture_touch(root, "class/pwm/pwmchip3/pwm-3:0/enable");
    pwm_init(&b, root);
    perr_clear(&e);
    CHECK_LL(pwm_configure(&b, s, 1, &e), 0);
    CHECK_STR(fixture_read(root, "class/pwm/pwmchip3/pwm-3:0/duty_cycle"), "1500000");
}

static void missing_chip_is_named(void)
{
    const char *root = fixture_tmpdir();
    struct pwm_bank b;
    struct perr e;
    struct servo_config s[1] = {servo("left", 7, 0, false)};
    char want[512];

    pwm_init(&b, root);
    perr_clear(&e);
    CHECK_LL(pwm_configure(&b, s, 1, &e), -1);
    CHECK_STR(e.reason, "sysfs");
    snprintf(want, sizeof want, "%s/class/pwm/pwmchip7/export", root);
    CHECK_STR(e.text, want);
    CHECK_STR(errno_atom(e.errnum), "enoent");
}

static void a_set_with_a_missing_chip_leaves_the_servos_running(void)
{
    const char *root = fixture_tmpdir();
    struct pwm_bank b;
    struct perr e;
    struct servo_config s[2] = {servo("left", 0, 0, false), servo("far", 7, 0, false)};
    struct servo_velocity go[1] = {{"left", 100}};

    fixture_pwm(root, 0, 0, true);
    pwm_init(&b, root);
    perr_clear(&e);
    CHECK_LL(pwm_configure(&b, s, 1, &e), 0);
    CHECK_LL(pwm_enable(&b, true, &e), 0);
    CHECK_LL(pwm_set(&b, go, 1, &e), 0);
    CHECK_LL(pwm_configure(&b, s, 2, &e), -1);
    CHECK_STR(e.reason, "sysfs");
    CHECK_LL(b.n, 1);
    CHECK_STR(fixture_read(root, "class/pwm/pwmchip0/pwm0/duty_cycle"), "2000000");
    CHECK_STR(fixture_read(root, "class/pwm/pwmchip0/pwm0/enable"), "1");
    CHECK_LL(pwm_set(&b, go, 1, &e), 0);
}

static void duplicates_are_refused_and_dropped_servos_disabled(void)
{
    const char *root = fixture_tmpdir();
    struct pwm_bank b;
    struct perr e;
    struct servo_config two[2] = {servo("left", 0, 0, false), servo("right", 0, 1, false)};
    struct servo_config dup_id[2] = {servo("left", 0, 0, false), servo("left", 0, 1, false)};
    struct servo_config dup_ch[2] = {servo("left", 0, 0, false), servo("right", 0, 0, false)};

    fixture_pwm(root, 0, 0, true);
    fixture_pwm(root, 0, 1, true);
    pwm_init(&b, root);
    perr_clear(&e);
    CHECK_LL(pwm_configure(&b, dup_id, 2, &e), -1);
    CHECK_STR(e.reason, "duplicate_servo");
    CHECK_LL(pwm_configure(&b, dup_ch, 2, &e), -1);
    CHECK_STR(e.reason, "duplicate_pwm_channel");
    CHECK_LL(pwm_configure(&b, two, 2, &e), 0);
    CHECK_LL(pwm_enable(&b, true, &e), 0);
    CHECK_LL(pwm_configure(&b, two, 1, &e), 0);   /* right leaves the set */
    CHECK_STR(fixture_read(root, "class/pwm/pwmchip0/pwm1/enable"), "0");
    CHECK_STR(fixture_read(root, "class/pwm/pwmchip0/pwm0/enable"), "1");
}

const struct test_case pwm_tests[] = {
    TEST_CASE(pulse_width_follows_velocity),
    TEST_CASE(pulse_rounds_symmetrically),
    TEST_CASE(calibration_is_checked),
    TEST_CASE(configure_writes_period_then_neutral),
    TEST_CASE(set_enable_and_neutral_write_duty_cycle),
    TEST_CASE(a_refused_set_writes_nothing),
    TEST_CASE(exports_a_missing_channel),
    TEST_CASE(finds_the_pwm_dash_chip_colon_channel_layout),
    TEST_CASE(missing_chip_is_named),
    TEST_CASE(a_set_with_a_missing_chip_leaves_the_servos_running),
    TEST_CASE(duplicates_are_refused_and_dropped_servos_disabled),
    {NULL, NULL},
};
