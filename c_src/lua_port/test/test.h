/* lua_port's test cases, on the shared harness (c_src/test_harness).
 * Run from test/ (fixtures/ holds Lua files). */
#ifndef TEST_H
#define TEST_H

#include <stdbool.h>
#include <stddef.h>
#include <stdio.h>
#include <string.h>

#include <ei.h>

#include "harness.h"

extern const struct test_case frame_tests[];
extern const struct test_case term_tests[];
extern const struct test_case port_tests[];

/* The term in an encoded buffer (with version byte) as text, e.g.
 * "{reply,1,ok}"; a static buffer. */
const char *term_text(const char *buf, int len);

#endif
