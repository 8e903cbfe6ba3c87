/* The C test harness the port programs share (pru_port, lua_port): each
 * case is a function that passes when all its checks hold; run_suites()
 * runs them and prints "N passed, N failed" last, the line make test
 * counts. A program's test/test.h includes this and lists its suites. */
#ifndef TEST_HARNESS_H
#define TEST_HARNESS_H

#include <stdbool.h>
#include <stddef.h>
#include <stdio.h>
#include <string.h>

/* Set by a failing check; defined once in the program's run_tests.c. */
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

/* Runs every case of the n suites (each ended by a case with no name),
 * calling after_each (when not NULL) after each one; prints each failure
 * and the closing count; returns the process's exit status. */
static inline int run_suites(const struct test_case *const *suites, size_t n,
                             void (*after_each)(void))
{
    int passed = 0, failed = 0;

    for (size_t s = 0; s < n; s++) {
        for (const struct test_case *t = suites[s]; t->name != NULL; t++) {
            test_case_failed = false;
            t->fn();
            if (after_each != NULL)
                after_each();
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

#endif
