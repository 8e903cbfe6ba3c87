/* pru_port's test cases and fixtures, on the shared harness
 * (c_src/test_harness). */
#ifndef TEST_H
#define TEST_H

#include <stdbool.h>
#include <stddef.h>
#include <stdio.h>
#include <string.h>

#include <ei.h>

#include "harness.h"

/* Each test_*.c exports its cases. */
extern const struct test_case adc_tests[];
extern const struct test_case protocol_tests[];
extern const struct test_case pwm_tests[];
extern const struct test_case watchdog_tests[];
extern const struct test_case gpio_tests[];
extern const struct test_case backend_tests[];
extern const struct test_case port_tests[];

/* ---- fixtures (fixtures.c) ---- */

/* A fresh directory under $TMPDIR; removed by fixture_cleanup(). */
const char *fixture_tmpdir(void);
void fixture_cleanup(void);
/* Creates root/rel as an empty file (and its parent directories). */
void fixture_touch(const char *root, const char *rel);
void fixture_mkdir(const char *root, const char *rel);
/* Writes text into root/rel. */
void fixture_write(const char *root, const char *rel, const char *text);
/* root/rel's content with the trailing newline removed, in a static
 * buffer; "<missing>" when it cannot be read. */
const char *fixture_read(const char *root, const char *rel);
/* A fake PWM chip: pwmchipN/export and, with exported, pwmM/{period,duty_cycle,enable}. */
void fixture_pwm(const char *root, int chip, int channel, bool exported);

/* The term in an encoded buffer (with version byte) as text, e.g.
 * "{reply,1,ok}"; a static buffer. */
const char *term_text(const char *buf, int len);

#endif
