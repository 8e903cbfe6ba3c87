/* The port, one frame at a time: requests on Lua states, the Torocó API
 * inside them, limits and bad frames (PROTOCOL.md). */
#include "test.h"

#include <stdlib.h>

#include "port.h"

static char reply[8192];

/* Runs one request frame; the reply as text. */
static const char *handle(struct port *p, ei_x_buff *req)
{
    ei_x_buff out;

    port_handle(p, (const unsigned char *)req->buff, (size_t)req->index, &out);
    snprintf(reply, sizeof reply, "%s", term_text(out.buff, out.index));
    ei_x_free(&out);
    ei_x_free(req);
    return reply;
}

static void head(ei_x_buff *x, const char *op, int arity, long ref)
{
    ei_x_new_with_version(x);
    ei_x_encode_tuple_header(x, arity);
    ei_x_encode_atom(x, op);
    ei_x_encode_long(x, ref);
}

static void bin(ei_x_buff *x, const char *s)
{
    ei_x_encode_binary(x, s, (long)strlen(s));
}

static const char *open_file(struct port *p, long id, const char *file, long budget, long mem)
{
    ei_x_buff x;

    head(&x, "open", 9, 1);
    ei_x_encode_long(&x, id);
    ei_x_encode_long(&x, 1000);
    bin(&x, file);
    bin(&x, "fixtures");
    ei_x_encode_map_header(&x, 1);
    ei_x_encode_atom(&x, "level");
    ei_x_encode_long(&x, 7);
    ei_x_encode_long(&x, budget);
    ei_x_encode_long(&x, mem);
    return handle(p, &x);
}

/* {input, Ref, Id, Now, Input, Value}; value: a pair of ints, or an atom */
static const char *input2(struct port *p, long id, long now, const char *in, long a, long b)
{
    ei_x_buff x;

    head(&x, "input", 6, 2);
    ei_x_encode_long(&x, id);
    ei_x_encode_long(&x, now);
    ei_x_encode_atom(&x, in);
    ei_x_encode_tuple_header(&x, 2);
    ei_x_encode_long(&x, a);
    ei_x_encode_long(&x, b);
    return handle(p, &x);
}

static const char *input_atom(struct port *p, long id, const char *in, const char *v)
{
    ei_x_buff x;

    head(&x, "input", 6, 3);
    ei_x_encode_long(&x, id);
    ei_x_encode_long(&x, 5000);
    ei_x_encode_atom(&x, in);
    bin(&x, v);
    return handle(p, &x);
}

static const char *timer(struct port *p, long id, long task, long seq)
{
    ei_x_buff x;

    head(&x, "timer", 6, 4);
    ei_x_encode_long(&x, id);
    ei_x_encode_long(&x, 9000);
    ei_x_encode_long(&x, task);
    ei_x_encode_long(&x, seq);
    return handle(p, &x);
}

static const char *on_state(struct port *p, const char *op, long id)
{
    ei_x_buff x;

    head(&x, op, 3, 5);
    ei_x_encode_long(&x, id);
    return handle(p, &x);
}

#define BUDGET 1000000
#define MEM (4 << 20)

static void ping_answers_the_protocol_version(void)
{
    struct port *p = port_new();
    ei_x_buff x;

    head(&x, "ping", 2, 42);
    CHECK_STR(handle(p, &x), "{reply,42,{pong,1}}");
    port_free(p);
}

static void a_trigger_latches_and_waits_with_a_timeout(void)
{
    struct port *p = port_new();

    CHECK_STR(open_file(p, 1, "echo.lua", BUDGET, MEM), "{reply,1,{ok,[]}}");
    /* task 1 is the file's body, task 2 the trigger */
    CHECK_STR(input2(p, 1, 1100, "x", 20, 20),
              "{reply,2,{ok,[{print,<<\"x\tx\t20\t20\">>},"
              "{set,<<\"motors_setvel\">>,{20,20}},"
              "{timer,2,1,500}]}}");
    CHECK_STR(on_state(p, "waits", 1), "{reply,5,{ok,[[2,<<\"trigger\">>,<<\"x\">>,true]]}}");
    /* the timeout: wait_for_input gives nil, so {v} holds no value */
    CHECK_STR(timer(p, 1, 2, 1), "{reply,4,{ok,[{send,<<\"out\">>,{},250}]}}");
    /* a stale timer (an old sequence number) does nothing */
    CHECK_STR(timer(p, 1, 2, 1), "{reply,4,{ok,[]}}");
    /* an input before the timeout cancels it */
    (void)input2(p, 1, 1200, "x", 1, 2);
    CHECK_STR(input2(p, 1, 1300, "x", 3, 4),
              "{reply,2,{ok,[{cancel,2},{send,<<\"out\">>,3,250}]}}");
    CHECK_STR(on_state(p, "close", 1), "{reply,5,ok}");
    CHECK_STR(on_state(p, "close", 1), "{reply,5,{error,{unknown_state,1}}}");
    port_free(p);
}

static void a_coroutine_sleeps_on_a_timer_and_reads_params(void)
{
    struct port *p = port_new();

    CHECK_STR(open_file(p, 3, "sleeper.lua", BUDGET, MEM),
              "{reply,1,{ok,[{set,<<\"led\">>,7},{timer,2,1,2000}]}}");
    CHECK_STR(timer(p, 3, 2, 1),
              "{reply,4,{ok,[{unset,all},{send,<<\"done\">>,{},default}]}}");
    CHECK_STR(on_state(p, "waits", 3), "{reply,5,{ok,[]}}");
    port_free(p);
}

static void a_lua_error_names_file_and_line(void)
{
    struct port *p = port_new();

    CHECK_STR(open_file(p, 4, "error.lua", BUDGET, MEM), "{reply,1,{ok,[]}}");
    CHECK_STR(input2(p, 4, 1, "go", 1, 2),
              "{reply,2,{stopped,{lua_error,<<\"error.lua\">>,4,"
              "<<\"attempt to index local 'v' (a number value)\">>},[]}}");
    CHECK_LL(port_states(p), 0);             /* a stopped state is gone */
    port_free(p);
}

static void a_syntax_error_stops_at_open(void)
{
    struct port *p = port_new();

    CHECK(strstr(open_file(p, 5, "syntax.lua", BUDGET, MEM),
                 "{stopped,{lua_error,<<\"syntax.lua\">>,3,") != NULL);
    CHECK(strstr(open_file(p, 6, "missing.lua", BUDGET, MEM), "{stopped,{lua_error,") != NULL);
    CHECK_LL(port_states(p), 0);
    port_free(p);
}

static void an_endless_loop_exhausts_the_budget_even_under_pcall(void)
{
    struct port *p = port_new();

    CHECK_STR(open_file(p, 7, "loop.lua", BUDGET, MEM), "{reply,1,{ok,[]}}");
    CHECK_STR(input2(p, 7, 1, "go", 0, 0),
              "{reply,2,{stopped,{lua_limit,<<\"loop.lua\">>,budget},[]}}");
    port_free(p);
}

static void allocation_without_end_hits_the_memory_cap(void)
{
    struct port *p = port_new();

    CHECK_STR(open_file(p, 8, "hog.lua", 100000000, MEM), "{reply,1,{ok,[]}}");
    CHECK_STR(input2(p, 8, 1, "go", 0, 0),
              "{reply,2,{stopped,{lua_limit,<<\"hog.lua\">>,memory},[]}}");
    /* a cap below an empty state's needs stops at open */
    CHECK(strstr(open_file(p, 9, "echo.lua", BUDGET, 1024), "memory}") != NULL);
    port_free(p);
}

static void the_sandbox_keeps_only_safe_libraries(void)
{
    struct port *p = port_new();

    CHECK_STR(open_file(p, 10, "sandbox.lua", BUDGET, MEM), "{reply,1,{ok,[]}}");
    CHECK_STR(input_atom(p, 10, "probe", "globals"),
              "{reply,3,{ok,[{send,<<\"r\">>,{<<\"nil\">>,<<\"nil\">>,"
              "<<\"nil\">>,<<\"nil\">>,<<\"nil\">>,<<\"nil\">>,"
              "<<\"nil\">>,42},default}]}}");
    /* the clock is the one the owner passed in: 5000 ms, the state opened at 1000 */
    CHECK_STR(input_atom(p, 10, "probe", "clock"),
              "{reply,3,{ok,[{send,<<\"r\">>,{5,4},default}]}}");
    CHECK(strstr(input_atom(p, 10, "probe", "binary"), "binary chunks are refused") != NULL);
    CHECK(strstr(input_atom(p, 10, "probe", "escape"), "{stopped,{lua_error,") != NULL);
    port_free(p);
}

static void bad_frames_get_an_error_not_a_crash(void)
{
    struct port *p = port_new();
    ei_x_buff x;
    const unsigned char junk[] = {131, 104, 3, 100};

    CHECK_STR(open_file(p, 11, "echo.lua", BUDGET, MEM), "{reply,1,{ok,[]}}");
    ei_x_new(&x);
    ei_x_append_buf(&x, (const char *)junk, sizeof junk);
    CHECK_STR(handle(p, &x), "{bad_frame,not_a_term}");
    ei_x_new_with_version(&x);
    ei_x_encode_atom(&x, "hello");
    CHECK_STR(handle(p, &x), "{bad_frame,not_a_request}");
    head(&x, "launch", 2, 9);
    CHECK_STR(handle(p, &x), "{reply,9,{error,{bad_request,9}}}");
    head(&x, "input", 3, 10);
    ei_x_encode_long(&x, 11);
    CHECK_STR(handle(p, &x), "{reply,10,{error,{bad_request,10}}}");
    CHECK_STR(input2(p, 99, 1, "x", 1, 1), "{reply,2,{error,{unknown_state,99}}}");
    head(&x, "input", 6, 12);                /* 201 values: refused, nothing ran */
    ei_x_encode_long(&x, 11);
    ei_x_encode_long(&x, 1);
    ei_x_encode_atom(&x, "x");
    ei_x_encode_tuple_header(&x, 201);
    for (int k = 0; k < 201; k++)
        ei_x_encode_long(&x, k);
    CHECK_STR(handle(p, &x), "{reply,12,{error,{bad_value,11}}}");
    CHECK_STR(open_file(p, 11, "echo.lua", BUDGET, MEM), "{reply,1,{error,{duplicate_state,11}}}");
    /* the state is still there and answers */
    CHECK(strstr(input2(p, 11, 1, "x", 5, 6), "{set,") != NULL);
    port_free(p);
}

static void an_idle_state_is_small(void)
{
    struct port *p = port_new();
    long long bytes;

    (void)open_file(p, 12, "echo.lua", BUDGET, MEM);
    (void)on_state(p, "memory", 12);
    CHECK(sscanf(reply, "{reply,5,{ok,%lld}}", &bytes) == 1);
    CHECK(bytes > 1000 && bytes < 200000);
    port_free(p);
}

static void a_main_file_records_its_wiring(void)
{
    struct port *p = port_new();

    CHECK_STR(open_file(p, 13, "main.lua", BUDGET, MEM),
              "{reply,1,{ok,["
              "{main,<<\"load_behavior\">>,6,[<<\"avoid\">>,<<\"behaviors/avoid\">>,#{<<\"speed\">>=>20}]},"
              "{main,<<\"set_inputs\">>,7,[<<\"avoid\">>,#{<<\"update\">>=>[[<<\"ir\">>,<<\"left\">>]]}]},"
              "{main,<<\"set_inputs\">>,8,[<<\"motors\">>,#{<<\"setvel2mtr\">>=>"
              "[[<<\"cruise\">>,<<\"motors\">>],[<<\"avoid\">>,<<\"motors\">>]]}]},"
              "{main,<<\"set_inhibitors\">>,9,[<<\"cruise\">>,#{<<\"motors\">>=>[[<<\"avoid\">>,<<\"busy\">>]]}]},"
              "{main,<<\"run\">>,10,[]}]}}");
    port_free(p);
}

static void holds_unsets_and_prints_cross_as_actions(void)
{
    struct port *p = port_new();

    CHECK_STR(open_file(p, 14, "outputs.lua", BUDGET, MEM), "{reply,1,{ok,[]}}");
    CHECK_STR(input2(p, 14, 1, "go", 3, 4),
              "{reply,2,{ok,[{print,<<\"go\t3\t4\tnil\">>},"
              "{send,<<\"held\">>,3,infinity},"
              "{set,<<\"latched\">>,{#{<<\"x\">>=>1},[<<\"two\">>]}},"
              "{unset,<<\"latched\">>},"
              "{send,<<\"timed\">>,{3,4},500},"
              "{unset,<<\"timed\">>}]}}");
    port_free(p);
}

static const char *attach(struct port *p, long id, long host, long slot)
{
    ei_x_buff x;

    head(&x, "attach", 6, 4);
    ei_x_encode_long(&x, id);
    ei_x_encode_long(&x, host);
    ei_x_encode_long(&x, slot);
    ei_x_encode_long(&x, 0);
    return handle(p, &x);
}

static const char *close_state(struct port *p, long id)
{
    ei_x_buff x;

    head(&x, "close", 3, 5);
    ei_x_encode_long(&x, id);
    return handle(p, &x);
}

static void an_inline_behavior_outlives_its_creator_and_fails_alone(void)
{
    struct port *p = port_new();

    CHECK_STR(open_file(p, 20, "host.lua", BUDGET, MEM), "{reply,1,{ok,[]}}");
    CHECK_STR(input_atom(p, 20, "make", "now"),
              "{reply,3,{ok,[{main,<<\"add_behavior\">>,7,[<<\"child\">>,1]}]}}");
    CHECK_STR(attach(p, 21, 20, 2), "{reply,4,{error,{unknown_slot,2}}}");
    CHECK_STR(attach(p, 21, 20, 1), "{reply,4,{ok,[]}}");
    /* the creator's input does not reach the child's tasks, nor the reverse */
    CHECK_STR(input_atom(p, 20, "x", "a"), "{reply,3,{ok,[]}}");
    CHECK_STR(input_atom(p, 21, "x", "a"),
              "{reply,3,{ok,[{send,<<\"out\">>,{<<\"a\">>,1,<<\"kid\">>},default}]}}");
    /* the creator goes, its state stays for the child */
    CHECK_STR(close_state(p, 20), "{reply,5,ok}");
    CHECK_STR(input_atom(p, 21, "x", "b"),
              "{reply,3,{ok,[{send,<<\"out\">>,{<<\"b\">>,2,<<\"kid\">>},default}]}}");
    /* a failure ends the child alone; attached again, it starts anew in the
     * same state (its upvalue goes on counting) */
    CHECK(strstr(input_atom(p, 21, "x", "boom"), "{stopped,{lua_error,") != NULL);
    CHECK_LL(port_states(p), 0);
    CHECK_STR(attach(p, 22, 20, 1), "{reply,4,{ok,[]}}");
    CHECK_STR(input_atom(p, 22, "x", "c"),
              "{reply,3,{ok,[{send,<<\"out\">>,{<<\"c\">>,3,<<\"kid\">>},default}]}}");
    /* attached again (a reset): the new id takes the slot's place */
    CHECK_STR(attach(p, 24, 20, 1), "{reply,4,{ok,[]}}");
    CHECK_STR(input_atom(p, 22, "x", "d"), "{reply,3,{error,{unknown_state,22}}}");
    CHECK_STR(input_atom(p, 24, "x", "d"),
              "{reply,3,{ok,[{send,<<\"out\">>,{<<\"d\">>,4,<<\"kid\">>},default}]}}");
    /* the last behavior closed: the state goes */
    CHECK_STR(close_state(p, 24), "{reply,5,ok}");
    CHECK_STR(attach(p, 23, 20, 1), "{reply,4,{error,{unknown_state,20}}}");
    port_free(p);
}

static void an_empty_file_is_a_behavior_with_no_tasks(void)
{
    struct port *p = port_new();

    CHECK_STR(open_file(p, 30, "empty.lua", BUDGET, MEM),
              "{reply,1,{ok,[{warning,<<\"empty.lua returns nothing: a behavior with no tasks\">>}]}}");
    CHECK_LL(port_states(p), 1);
    port_free(p);
}

const struct test_case port_tests[] = {
    TEST_CASE(an_inline_behavior_outlives_its_creator_and_fails_alone),
    TEST_CASE(an_empty_file_is_a_behavior_with_no_tasks),
    TEST_CASE(ping_answers_the_protocol_version),
    TEST_CASE(a_trigger_latches_and_waits_with_a_timeout),
    TEST_CASE(a_coroutine_sleeps_on_a_timer_and_reads_params),
    TEST_CASE(a_lua_error_names_file_and_line),
    TEST_CASE(a_syntax_error_stops_at_open),
    TEST_CASE(an_endless_loop_exhausts_the_budget_even_under_pcall),
    TEST_CASE(allocation_without_end_hits_the_memory_cap),
    TEST_CASE(the_sandbox_keeps_only_safe_libraries),
    TEST_CASE(bad_frames_get_an_error_not_a_crash),
    TEST_CASE(an_idle_state_is_small),
    TEST_CASE(a_main_file_records_its_wiring),
    TEST_CASE(holds_unsets_and_prints_cross_as_actions),
    {NULL, NULL}};
