/* Framing, request decoding (good and bad frames) and reply encoding. */
#include "test.h"

#include <errno.h>
#include <stdlib.h>
#include <unistd.h>

#include "protocol.h"

/* Decodes an ei_x buffer through an exact-size heap copy, so that any read
 * past the frame's end shows up under valgrind/ASan. */
static enum decode_result decode_x(const ei_x_buff *x, struct request *r, struct perr *e)
{
    unsigned char *copy = malloc((size_t)x->index);
    enum decode_result d;

    memcpy(copy, x->buff, (size_t)x->index);
    d = protocol_decode(copy, (size_t)x->index, r, e);
    free(copy);
    return d;
}

static void req_head(ei_x_buff *x, long long ref)
{
    ei_x_new_with_version(x);
    ei_x_encode_tuple_header(x, 2);
    ei_x_encode_longlong(x, ref);
}

static void frames_are_reassembled_across_reads(void)
{
    struct frame_reader *r = malloc(sizeof *r);
    const unsigned char two[] = {0, 3, 'a', 'b', 'c', 0, 0, 0, 1, 'z'};
    const unsigned char *f;
    size_t len;

    frame_reader_init(r);
    CHECK(!frame_reader_next(r, &f, &len));
    frame_reader_push(r, two, 1);
    CHECK(!frame_reader_next(r, &f, &len));
    frame_reader_push(r, two + 1, 3);
    CHECK(!frame_reader_next(r, &f, &len));
    frame_reader_push(r, two + 4, sizeof two - 4);
    CHECK(frame_reader_next(r, &f, &len));
    CHECK_LL(len, 3);
    CHECK(memcmp(f, "abc", 3) == 0);
    CHECK(frame_reader_next(r, &f, &len));
    CHECK_LL(len, 0);                       /* an empty frame is still a frame */
    CHECK(frame_reader_next(r, &f, &len));
    CHECK_LL(len, 1);
    CHECK(f[0] == 'z');
    CHECK(!frame_reader_next(r, &f, &len));
    free(r);
}

static void largest_frame_fits_after_partial_one(void)
{
    struct frame_reader *r = malloc(sizeof *r);
    unsigned char *big = calloc(1, 2 + FRAME_MAX);
    const unsigned char *f;
    size_t len;

    frame_reader_init(r);
    big[0] = 0xff;
    big[1] = 0xff;
    CHECK_LL(frame_reader_push(r, big, 2 + FRAME_MAX - 10), 2 + FRAME_MAX - 10);
    CHECK(!frame_reader_next(r, &f, &len));
    CHECK_LL(frame_reader_push(r, big, 10), 10);
    CHECK(frame_reader_next(r, &f, &len));
    CHECK_LL(len, FRAME_MAX);
    free(big);
    free(r);
}

static void frame_write_prefixes_length(void)
{
    int p[2];
    unsigned char buf[16];

    CHECK(pipe(p) == 0);
    CHECK_LL(frame_write(p[1], "hey", 3), 0);
    CHECK_LL(read(p[0], buf, sizeof buf), 5);
    CHECK(buf[0] == 0 && buf[1] == 3 && memcmp(buf + 2, "hey", 3) == 0);
    errno = 0;
    CHECK_LL(frame_write(p[1], "x", FRAME_MAX + 1), -1);
    CHECK_LL(errno, EMSGSIZE);
    close(p[0]);
    close(p[1]);
}

static void decodes_every_request(void)
{
    ei_x_buff x;
    struct request r;
    struct perr e;

    req_head(&x, 1);
    ei_x_encode_atom(&x, "ping");
    CHECK_LL(decode_x(&x, &r, &e), DECODE_OK);
    CHECK_LL(r.ref, 1);
    CHECK_LL(r.kind, REQ_PING);
    ei_x_free(&x);

    req_head(&x, 123456789012LL);
    ei_x_encode_tuple_header(&x, 2);
    ei_x_encode_atom(&x, "configure_adc");
    ei_x_encode_list_header(&x, 3);
    ei_x_encode_tuple_header(&x, 2);
    ei_x_encode_long(&x, 0);
    ei_x_encode_atom(&x, "analog");
    ei_x_encode_tuple_header(&x, 4);
    ei_x_encode_long(&x, 2);
    ei_x_encode_atom(&x, "analog_threshold");
    ei_x_encode_long(&x, 2000);
    ei_x_encode_long(&x, 1500);
    ei_x_encode_tuple_header(&x, 2);
    ei_x_encode_long(&x, 3);
    ei_x_encode_atom(&x, "off");
    ei_x_encode_empty_list(&x);
    CHECK_LL(decode_x(&x, &r, &e), DECODE_OK);
    CHECK_LL(r.ref, 123456789012LL);
    CHECK_LL(r.kind, REQ_CONFIGURE_ADC);
    CHECK_LL(r.u.adc.n, 3);
    CHECK_LL(r.u.adc.ch[0].mode, ADC_ANALOG);
    CHECK_LL(r.u.adc.ch[1].channel, 2);
    CHECK_LL(r.u.adc.ch[1].mode, ADC_THRESHOLD);
    CHECK_LL(r.u.adc.ch[1].high, 2000);
    CHECK_LL(r.u.adc.ch[1].low, 1500);
    CHECK_LL(r.u.adc.ch[2].mode, ADC_OFF);
    ei_x_free(&x);

    req_head(&x, 2);
    ei_x_encode_tuple_header(&x, 2);
    ei_x_encode_atom(&x, "configure_servos");
    ei_x_encode_list_header(&x, 1);
    ei_x_encode_tuple_header(&x, 7);
    ei_x_encode_atom(&x, "left");
    ei_x_encode_long(&x, 1);
    ei_x_encode_long(&x, 0);
    ei_x_encode_long(&x, 20000000);
    ei_x_encode_long(&x, 1500000);
    ei_x_encode_long(&x, 500000);
    ei_x_encode_boolean(&x, 1);
    ei_x_encode_empty_list(&x);
    CHECK_LL(decode_x(&x, &r, &e), DECODE_OK);
    CHECK_LL(r.kind, REQ_CONFIGURE_SERVOS);
    CHECK_LL(r.u.servos.n, 1);
    CHECK_STR(r.u.servos.s[0].id, "left");
    CHECK_LL(r.u.servos.s[0].pwmchip, 1);
    CHECK_LL(r.u.servos.s[0].period_ns, 20000000);
    CHECK(r.u.servos.s[0].reversed);
    ei_x_free(&x);

    req_head(&x, 3);
    ei_x_encode_tuple_header(&x, 2);
    ei_x_encode_atom(&x, "set_servos");
    ei_x_encode_list_header(&x, 2);
    ei_x_encode_tuple_header(&x, 2);
    ei_x_encode_atom(&x, "left");
    ei_x_encode_long(&x, -100);
    ei_x_encode_tuple_header(&x, 2);
    ei_x_encode_atom(&x, "right");
    ei_x_encode_long(&x, 55);
    ei_x_encode_empty_list(&x);
    CHECK_LL(decode_x(&x, &r, &e), DECODE_OK);
    CHECK_LL(r.kind, REQ_SET_SERVOS);
    CHECK_LL(r.u.set.n, 2);
    CHECK_LL(r.u.set.v[0].velocity, -100);
    CHECK_STR(r.u.set.v[1].id, "right");
    ei_x_free(&x);

    req_head(&x, 4);
    ei_x_encode_tuple_header(&x, 4);
    ei_x_encode_atom(&x, "configure_button");
    ei_x_encode_long(&x, 17);
    ei_x_encode_boolean(&x, 1);
    ei_x_encode_long(&x, 20);
    CHECK_LL(decode_x(&x, &r, &e), DECODE_OK);
    CHECK_LL(r.kind, REQ_CONFIGURE_BUTTON);
    CHECK(!r.u.button.none && r.u.button.active_low);
    CHECK_LL(r.u.button.line, 17);
    CHECK_LL(r.u.button.debounce_ms, 20);
    ei_x_free(&x);

    req_head(&x, 5);
    ei_x_encode_tuple_header(&x, 3);
    ei_x_encode_atom(&x, "sim_adc");
    ei_x_encode_long(&x, 1);
    ei_x_encode_long(&x, 4095);
    CHECK_LL(decode_x(&x, &r, &e), DECODE_OK);
    CHECK_LL(r.kind, REQ_SIM_ADC);
    CHECK_LL(r.u.sim_adc.value, 4095);
    ei_x_free(&x);

    req_head(&x, 6);
    ei_x_encode_tuple_header(&x, 2);
    ei_x_encode_atom(&x, "enable_servos");
    ei_x_encode_boolean(&x, 0);
    CHECK_LL(decode_x(&x, &r, &e), DECODE_OK);
    CHECK_LL(r.kind, REQ_ENABLE_SERVOS);
    CHECK(!r.u.enable);
    ei_x_free(&x);

    req_head(&x, 7);
    ei_x_encode_tuple_header(&x, 2);
    ei_x_encode_atom(&x, "configure_watchdog");
    ei_x_encode_long(&x, 250);
    CHECK_LL(decode_x(&x, &r, &e), DECODE_OK);
    CHECK_LL(r.u.watchdog_ms, 250);
    ei_x_free(&x);
}

static void garbage_and_truncation_are_bad_frames(void)
{
    const unsigned char junk[][6] = {{1, 2, 3}, {131}, {131, 104, 2}, {0}, {131, 200, 0}};
    const size_t junk_len[] = {3, 1, 3, 1, 3};
    ei_x_buff x;
    struct request r;
    struct perr e;

    for (size_t i = 0; i < sizeof junk_len / sizeof junk_len[0]; i++) {
        unsigned char *copy = malloc(junk_len[i]);
        memcpy(copy, junk[i], junk_len[i]);
        CHECK_LL(protocol_decode(copy, junk_len[i], &r, &e), DECODE_BAD_FRAME);
        CHECK_STR(e.reason, "bad_frame");
        CHECK_STR(e.text, "not_a_term");
        free(copy);
    }
    CHECK_LL(protocol_decode((const unsigned char *)"", 0, &r, &e), DECODE_BAD_FRAME);

    /* every strict prefix of a valid request is refused, reading no further */
    req_head(&x, 9);
    ei_x_encode_tuple_header(&x, 2);
    ei_x_encode_atom(&x, "set_servos");
    ei_x_encode_list_header(&x, 1);
    ei_x_encode_tuple_header(&x, 2);
    ei_x_encode_atom(&x, "left");
    ei_x_encode_long(&x, 1000000);
    ei_x_encode_empty_list(&x);
    for (int n = 1; n < x.index; n++) {
        unsigned char *copy = malloc((size_t)n);
        memcpy(copy, x.buff, (size_t)n);
        CHECK_LL(protocol_decode(copy, (size_t)n, &r, &e), DECODE_BAD_FRAME);
        free(copy);
    }
    /* and trailing bytes after a complete term too */
    {
        unsigned char *copy = malloc((size_t)x.index + 1);
        memcpy(copy, x.buff, (size_t)x.index);
        copy[x.index] = 0;
        CHECK_LL(protocol_decode(copy, (size_t)x.index + 1, &r, &e), DECODE_BAD_FRAME);
        free(copy);
    }
    ei_x_free(&x);
}

static void deep_nesting_and_foreign_terms_are_refused(void)
{
    ei_x_buff x;
    struct request r;
    struct perr e;

    ei_x_new_with_version(&x);
    for (int i = 0; i < 200; i++)
        ei_x_encode_tuple_header(&x, 1);
    ei_x_encode_atom(&x, "ping");
    CHECK_LL(decode_x(&x, &r, &e), DECODE_BAD_FRAME);
    ei_x_free(&x);

    /* a pid has no place in a request */
    {
        erlang_pid pid = {.node = "a@b", .num = 1, .serial = 0, .creation = 1};
        ei_x_new_with_version(&x);
        ei_x_encode_tuple_header(&x, 2);
        ei_x_encode_long(&x, 1);
        ei_x_encode_pid(&x, &pid);
        CHECK_LL(decode_x(&x, &r, &e), DECODE_BAD_FRAME);
        ei_x_free(&x);
    }
    /* a list claiming more elements than there are bytes */
    {
        unsigned char bomb[] = {131, 108, 0x7f, 0xff, 0xff, 0xff, 106};
        CHECK_LL(protocol_decode(bomb, sizeof bomb, &r, &e), DECODE_BAD_FRAME);
    }
}

static void wrong_shapes_name_the_request(void)
{
    ei_x_buff x;
    struct request r;
    struct perr e;

    /* not {Ref, Request} */
    ei_x_new_with_version(&x);
    ei_x_encode_tuple_header(&x, 2);
    ei_x_encode_atom(&x, "ref");
    ei_x_encode_atom(&x, "ping");
    CHECK_LL(decode_x(&x, &r, &e), DECODE_BAD_FRAME);
    CHECK_STR(e.text, "not_a_request");
    ei_x_free(&x);

    /* right ref, wrong arguments */
    req_head(&x, 41);
    ei_x_encode_tuple_header(&x, 2);
    ei_x_encode_atom(&x, "set_servos");
    ei_x_encode_atom(&x, "fast");
    CHECK_LL(decode_x(&x, &r, &e), DECODE_BAD_REQUEST);
    CHECK_LL(r.ref, 41);
    CHECK_STR(e.reason, "bad_request");
    CHECK_STR(e.text, "set_servos");
    ei_x_free(&x);

    /* an improper list */
    req_head(&x, 42);
    ei_x_encode_tuple_header(&x, 2);
    ei_x_encode_atom(&x, "configure_adc");
    ei_x_encode_list_header(&x, 1);
    ei_x_encode_tuple_header(&x, 2);
    ei_x_encode_long(&x, 0);
    ei_x_encode_atom(&x, "analog");
    ei_x_encode_atom(&x, "tail");
    CHECK_LL(decode_x(&x, &r, &e), DECODE_BAD_REQUEST);
    CHECK_STR(e.text, "configure_adc");
    ei_x_free(&x);

    /* unknown */
    req_head(&x, 43);
    ei_x_encode_tuple_header(&x, 2);
    ei_x_encode_atom(&x, "launch");
    ei_x_encode_long(&x, 1);
    CHECK_LL(decode_x(&x, &r, &e), DECODE_BAD_REQUEST);
    CHECK_STR(e.reason, "unknown_request");
    CHECK_STR(e.text, "launch");
    ei_x_free(&x);

    /* too many servos */
    req_head(&x, 44);
    ei_x_encode_tuple_header(&x, 2);
    ei_x_encode_atom(&x, "set_servos");
    ei_x_encode_list_header(&x, MAX_SERVOS + 1);
    for (int i = 0; i <= MAX_SERVOS; i++) {
        ei_x_encode_tuple_header(&x, 2);
        ei_x_encode_atom(&x, "s");
        ei_x_encode_long(&x, 0);
    }
    ei_x_encode_empty_list(&x);
    CHECK_LL(decode_x(&x, &r, &e), DECODE_BAD_REQUEST);
    CHECK_STR(e.reason, "too_many_servos");
    ei_x_free(&x);
}

static void replies_and_events_encode_as_documented(void)
{
    ei_x_buff x;
    struct perr e;

    encode_reply_ok(&x, 7);
    CHECK_STR(term_text(x.buff, x.index), "{reply,7,ok}");
    ei_x_free(&x);
    encode_reply_atom(&x, 8, "pong");
    CHECK_STR(term_text(x.buff, x.index), "{reply,8,pong}");
    ei_x_free(&x);
    perr_set_path(&e, "sysfs", "/sys/class/pwm/pwmchip0/export", 2 /* ENOENT */);
    encode_reply_error(&x, 9, &e);
    CHECK_STR(term_text(x.buff, x.index),
              "{reply,9,{error,{sysfs,\"/sys/class/pwm/pwmchip0/export\",enoent}}}");
    ei_x_free(&x);
    perr_set_atom(&e, "unknown_servo", "right");
    encode_reply_error(&x, 10, &e);
    CHECK_STR(term_text(x.buff, x.index), "{reply,10,{error,{unknown_servo,right}}}");
    ei_x_free(&x);
    perr_set(&e, "button_not_configured");
    encode_reply_error(&x, 11, &e);
    CHECK_STR(term_text(x.buff, x.index), "{reply,11,{error,button_not_configured}}");
    ei_x_free(&x);
    perr_set_atom(&e, "bad_frame", "not_a_term");
    encode_bad_frame(&x, &e);
    CHECK_STR(term_text(x.buff, x.index), "{error,{bad_frame,not_a_term}}");
    ei_x_free(&x);
    encode_adc_event(&x, 2, 1, 12345);
    CHECK_STR(term_text(x.buff, x.index), "{adc,2,1,12345}");
    ei_x_free(&x);
    encode_button_event(&x, true, 5);
    CHECK_STR(term_text(x.buff, x.index), "{button,pressed,5}");
    ei_x_free(&x);
    encode_watchdog_event(&x, 6);
    CHECK_STR(term_text(x.buff, x.index), "{watchdog,6}");
    ei_x_free(&x);
    encode_hello(&x, "sim");
    CHECK_STR(term_text(x.buff, x.index), "{hello,1,sim}");
    ei_x_free(&x);
}

const struct test_case protocol_tests[] = {
    TEST_CASE(frames_are_reassembled_across_reads),
    TEST_CASE(largest_frame_fits_after_partial_one),
    TEST_CASE(frame_write_prefixes_length),
    TEST_CASE(decodes_every_request),
    TEST_CASE(garbage_and_truncation_are_bad_frames),
    TEST_CASE(deep_nesting_and_foreign_terms_are_refused),
    TEST_CASE(wrong_shapes_name_the_request),
    TEST_CASE(replies_and_events_encode_as_documented),
    {NULL, NULL},
};
