/* Runs every C test case; the last line is "N passed, N failed". */
#include "test.h"

#include <stdlib.h>

bool test_case_failed;

int main(void)
{
    const struct test_case *suites[] = {adc_tests, protocol_tests, pwm_tests,
                                        watchdog_tests, gpio_tests, backend_tests,
                                        port_tests};
    int passed = 0, failed = 0;

    ei_init();
    for (size_t s = 0; s < sizeof suites / sizeof suites[0]; s++) {
        for (const struct test_case *t = suites[s]; t->name != NULL; t++) {
            test_case_failed = false;
            t->fn();
            fixture_cleanup();
            if (test_case_failed) {
                failed++;
                printf("FAIL %s\n", t->name);
            } else {
                passed++;
            }
            fflush(stdout);
        }
    }
    printf("%d passed, %d failed\n", passed, failed);
    return failed == 0 ? 0 : 1;
}
