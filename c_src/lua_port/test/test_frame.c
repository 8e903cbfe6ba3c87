/* {packet, 4} framing: reassembly, oversized frames, writing. */
#include "test.h"

#include <stdlib.h>
#include <unistd.h>

#include "frame.h"

static void frames_are_reassembled_across_reads(void)
{
    struct frame_reader r;
    const unsigned char two[] = {0, 0, 0, 3, 'a', 'b', 'c', 0, 0, 0, 0, 0, 0, 0, 1, 'z'};
    const unsigned char *f;
    size_t len;

    CHECK(frame_reader_init(&r) == 0);
    CHECK(frame_reader_next(&r, &f, &len) == FRAME_NONE);
    frame_reader_push(&r, two, 3);
    CHECK(frame_reader_next(&r, &f, &len) == FRAME_NONE);
    frame_reader_push(&r, two + 3, 3);
    CHECK(frame_reader_next(&r, &f, &len) == FRAME_NONE);
    frame_reader_push(&r, two + 6, sizeof two - 6);
    CHECK(frame_reader_next(&r, &f, &len) == FRAME_READY);
    CHECK_LL(len, 3);
    CHECK(memcmp(f, "abc", 3) == 0);
    CHECK(frame_reader_next(&r, &f, &len) == FRAME_READY);
    CHECK_LL(len, 0);                        /* an empty frame is still a frame */
    CHECK(frame_reader_next(&r, &f, &len) == FRAME_READY);
    CHECK_LL(len, 1);
    CHECK(f[0] == 'z');
    CHECK(frame_reader_next(&r, &f, &len) == FRAME_NONE);
    frame_reader_free(&r);
}

static void an_oversized_frame_is_reported_and_skipped(void)
{
    struct frame_reader r;
    size_t big = FRAME_MAX + 10;
    unsigned char head[4] = {(unsigned char)(big >> 24), (unsigned char)(big >> 16),
                             (unsigned char)(big >> 8), (unsigned char)big};
    unsigned char *junk = calloc(1, 4096);
    const unsigned char next[] = {0, 0, 0, 2, 'o', 'k'};
    const unsigned char *f;
    size_t len, left = big;

    CHECK(frame_reader_init(&r) == 0);
    frame_reader_push(&r, head, 4);
    CHECK(frame_reader_next(&r, &f, &len) == FRAME_TOO_BIG);
    CHECK_LL(len, big);
    while (left > 0) {
        size_t n = left < 4096 ? left : 4096;
        CHECK_LL(frame_reader_push(&r, junk, n), n);
        CHECK(frame_reader_next(&r, &f, &len) == FRAME_NONE);
        left -= n;
    }
    frame_reader_push(&r, next, sizeof next);
    CHECK(frame_reader_next(&r, &f, &len) == FRAME_READY);
    CHECK_LL(len, 2);
    CHECK(memcmp(f, "ok", 2) == 0);
    frame_reader_free(&r);
    free(junk);
}

static void the_largest_frame_fits(void)
{
    struct frame_reader r;
    unsigned char *big = calloc(1, 4 + FRAME_MAX);
    const unsigned char *f;
    size_t len;

    big[1] = (unsigned char)(FRAME_MAX >> 16);
    big[2] = (unsigned char)(FRAME_MAX >> 8);
    big[3] = (unsigned char)FRAME_MAX;
    CHECK(frame_reader_init(&r) == 0);
    CHECK_LL(frame_reader_push(&r, big, 4 + FRAME_MAX), 4 + FRAME_MAX);
    CHECK(frame_reader_next(&r, &f, &len) == FRAME_READY);
    CHECK_LL(len, FRAME_MAX);
    frame_reader_free(&r);
    free(big);
}

static void written_frames_read_back(void)
{
    int fds[2];
    struct frame_reader r;
    const unsigned char *f;
    size_t len;

    CHECK(pipe(fds) == 0);
    CHECK(frame_write(fds[1], "hello", 5) == 0);
    CHECK(frame_reader_init(&r) == 0);
    CHECK_LL(frame_reader_fill(&r, fds[0]), 9);
    CHECK(frame_reader_next(&r, &f, &len) == FRAME_READY);
    CHECK_LL(len, 5);
    CHECK(memcmp(f, "hello", 5) == 0);
    close(fds[0]);
    close(fds[1]);
    frame_reader_free(&r);
}

/* Answers gathered go out in one write: one read takes them all, whole. */
static void gathered_frames_go_out_in_one_write(void)
{
    int fds[2];
    struct frame_reader r;
    struct frame_out o = {0};
    const unsigned char *f;
    size_t len;
    char big[10000];

    memset(big, 'x', sizeof big);
    CHECK(pipe(fds) == 0);
    CHECK(frame_out_add(&o, "one", 3) == 0);
    CHECK(frame_out_add(&o, big, sizeof big) == 0);    /* past the first allocation */
    CHECK(frame_out_add(&o, "three", 5) == 0);
    CHECK(frame_out_flush(&o, fds[1]) == 0);
    CHECK_LL(o.len, 0);
    CHECK(frame_reader_init(&r) == 0);
    CHECK_LL(frame_reader_fill(&r, fds[0]), 3 * 4 + 3 + sizeof big + 5);
    CHECK(frame_reader_next(&r, &f, &len) == FRAME_READY);
    CHECK(len == 3 && memcmp(f, "one", 3) == 0);
    CHECK(frame_reader_next(&r, &f, &len) == FRAME_READY);
    CHECK(len == sizeof big && memcmp(f, big, sizeof big) == 0);
    CHECK(frame_reader_next(&r, &f, &len) == FRAME_READY);
    CHECK(len == 5 && memcmp(f, "three", 5) == 0);
    CHECK(frame_reader_next(&r, &f, &len) == FRAME_NONE);
    frame_out_free(&o);
    close(fds[0]);
    close(fds[1]);
    frame_reader_free(&r);
}

const struct test_case frame_tests[] = {
    TEST_CASE(gathered_frames_go_out_in_one_write),
    TEST_CASE(frames_are_reassembled_across_reads),
    TEST_CASE(an_oversized_frame_is_reported_and_skipped),
    TEST_CASE(the_largest_frame_fits),
    TEST_CASE(written_frames_read_back),
    {NULL, NULL}};
