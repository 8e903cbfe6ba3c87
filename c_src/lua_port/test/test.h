/* A very small test harness (the shape of pru_port's): each case is a
 * function; a case passes when all its checks hold. run_tests prints
 * "N passed, N failed" last. Run from test/ (fixtures/ holds Lua files). */
#ifndef TEST_H
#define TEST_H

#include <stdbool.h>
#include <stddef.h>
#include <stdio.h>
#include <string.h>

#include <ei.h>

extern bool test_case_failed;

#define CHECK(cond)                                                            \
    do {                                                                       \
        if (!(cond)) {                                                         \
            test_case_failed = true;                                           \
            fprintf(stderr, "  check failed %s:%d: %s\n", __FILE__, __LINE__, #cond); \
        }                                                                      \
    } while (0)

#define CHECK_LL(a, b)                                                         \
    do {                                                                       \
        long long a_ = (long long)(a), b_ = (long long)(b);                    \
        if (a_ != b_) {                                                        \
            test_case_failed = true;                                           \
            fprintf(stderr, "  check failed %s:%d: %s == %lld, expected %lld\n", \
                    __FILE__, __LINE__, #a, a_, b_);                           \
        }                                                                      \
    } while (0)

#define CHECK_STR(a, b)                                                        \
    do {                                                                       \
        const char *a_ = (a), *b_ = (b);                                       \
        if (a_ == NULL || strcmp(a_, b_) != 0) {                               \
            test_case_failed = true;                                           \
            fprintf(stderr, "  check failed %s:%d: %s is\n    %s\n  expected\n    %s\n", \
                    __FILE__, __LINE__, #a, a_ ? a_ : "(null)", b_);           \
        }                                                                      \
    } while (0)

typedef void (*test_fn)(void);
struct test_case {
    const char *name;
    test_fn fn;
};
#define TEST_CASE(fn) {#fn, fn}

extern const struct test_case frame_tests[];
extern const struct test_case term_tests[];
extern const struct test_case port_tests[];

/* The term in an encoded buffer (with version byte) as text, e.g.
 * "{reply,1,ok}"; a static buffer. */
const char *term_text(const char *buf, int len);

#endif
