/* Button polarity and debouncing; libgpiod error reporting. */
#include "test.h"

#include "gpio.h"

static void edges_follow_polarity(void)
{
    struct button b;

    button_init(&b);
    CHECK_LL(button_input(&b, 1, 0), BUTTON_NONE);   /* unconfigured: silent */
    button_configure(&b, true, 0, 1);                 /* active low, line high: released */
    CHECK_LL(button_input(&b, 1, 1), BUTTON_NONE);
    CHECK_LL(button_input(&b, 0, 2), BUTTON_PRESSED);
    CHECK_LL(button_input(&b, 0, 3), BUTTON_NONE);
    CHECK_LL(button_input(&b, 1, 4), BUTTON_RELEASED);
    button_configure(&b, false, 0, 0);
    CHECK_LL(button_input(&b, 1, 5), BUTTON_PRESSED);
}

static void debounce_reports_only_a_level_that_holds(void)
{
    struct button b;

    button_init(&b);
    button_configure(&b, false, 20, 0);
    /* bounce: 1 0 1 0 1 within the debounce time, settling pressed */
    for (int i = 0; i < 5; i++)
        CHECK_LL(button_input(&b, (i + 1) % 2, 100 + i * 3), BUTTON_NONE);
    CHECK_LL(button_timeout(&b, 112), 20);
    CHECK_LL(button_settle(&b, 131), BUTTON_NONE);
    CHECK_LL(button_settle(&b, 132), BUTTON_PRESSED);
    CHECK_LL(button_settle(&b, 200), BUTTON_NONE);
    CHECK_LL(button_timeout(&b, 200), -1);
    /* a glitch that comes back to the reported level reports nothing */
    CHECK_LL(button_input(&b, 0, 300), BUTTON_NONE);
    CHECK_LL(button_input(&b, 1, 305), BUTTON_NONE);
    CHECK_LL(button_settle(&b, 400), BUTTON_NONE);
}

static void missing_gpiochip_is_named(void)
{
    struct button b;
    struct perr e;
    const char *root = fixture_tmpdir();
    char path[512];

    snprintf(path, sizeof path, "%s/gpiochip9", root);
    button_init(&b);
    perr_clear(&e);
    CHECK_LL(button_open_gpiod(&b, path, 3, true, 0, &e), -1);
    CHECK_STR(e.reason, "gpiochip");
    CHECK_STR(e.text, path);
    CHECK(e.errnum != 0);
    CHECK(!b.configured);
    CHECK_LL(b.fd, -1);
    /* a regular file is no gpiochip either */
    fixture_touch(root, "gpiochip9");
    CHECK_LL(button_open_gpiod(&b, path, 3, true, 0, &e), -1);
    CHECK_STR(e.reason, "gpiochip");
    CHECK_LL(button_open_gpiod(&b, path, -1, true, 0, &e), -1);
    CHECK_STR(e.reason, "bad_gpio_line");
}

const struct test_case gpio_tests[] = {
    TEST_CASE(edges_follow_polarity),
    TEST_CASE(debounce_reports_only_a_level_that_holds),
    TEST_CASE(missing_gpiochip_is_named),
    {NULL, NULL},
};
