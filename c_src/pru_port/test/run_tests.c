/* Runs every C test case; the last line is "N passed, N failed". */
#include "test.h"

#include <stdlib.h>

bool test_case_failed;

int main(void)
{
    const struct test_case *suites[] = {adc_tests, protocol_tests, pwm_tests,
                                        watchdog_tests, gpio_tests, backend_tests,
                                        port_tests};

    ei_init();
    return run_suites(suites, sizeof suites / sizeof suites[0], fixture_cleanup);
}
