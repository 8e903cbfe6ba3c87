/* The whole loop: port_run in a child process, talked to over pipes as
 * the Erlang owner would, with servos on a fake sysfs tree. */
#include "test.h"

#include <poll.h>
#include <signal.h>
#include <stdlib.h>
#include <sys/wait.h>
#include <unistd.h>

#include "port.h"
#include "protocol.h"

struct child {
    pid_t pid;
    int to;
    int from;
};

static struct child start(const struct port_opts *o)
{
    int in[2], out[2];
    struct child c = {-1, -1, -1};

    if (pipe(in) != 0 || pipe(out) != 0)
        return c;
    fflush(NULL);
    c.pid = fork();
    if (c.pid == 0) {
        close(in[1]);
        close(out[0]);
        _exit(port_run(o, in[0], out[1]));
    }
    close(in[0]);
    close(out[1]);
    c.to = in[1];
    c.from = out[0];
    return c;
}

/* The next frame as text, or "<timeout>" / "<closed>". */
static const char *next_term(struct child *c, int timeout_ms)
{
    static char buf[FRAME_MAX + 2];
    unsigned char head[2];
    size_t need, got = 0;
    struct pollfd p = {.fd = c->from, .events = POLLIN};

    if (poll(&p, 1, timeout_ms) <= 0)
        return "<timeout>";
    if (read(c->from, head, 2) != 2)
        return "<closed>";
    need = ((size_t)head[0] << 8) | head[1];
    while (got < need) {
        ssize_t n = read(c->from, buf + got, need - got);
        if (n <= 0)
            return "<closed>";
        got += (size_t)n;
    }
    return term_text(buf, (int)need);
}

static void send_x(struct child *c, ei_x_buff *x)
{
    CHECK_LL(frame_write(c->to, x->buff, (size_t)x->index), 0);
    ei_x_free(x);
}

static void send_simple(struct child *c, long long ref, const char *tag, long long arg)
{
    ei_x_buff x;
    ei_x_new_with_version(&x);
    ei_x_encode_tuple_header(&x, 2);
    ei_x_encode_longlong(&x, ref);
    ei_x_encode_tuple_header(&x, 2);
    ei_x_encode_atom(&x, tag);
    ei_x_encode_longlong(&x, arg);
    send_x(c, &x);
}

static void send_servo(struct child *c, long long ref)
{
    ei_x_buff x;
    ei_x_new_with_version(&x);
    ei_x_encode_tuple_header(&x, 2);
    ei_x_encode_longlong(&x, ref);
    ei_x_encode_tuple_header(&x, 2);
    ei_x_encode_atom(&x, "configure_servos");
    ei_x_encode_list_header(&x, 1);
    ei_x_encode_tuple_header(&x, 7);
    ei_x_encode_atom(&x, "left");
    ei_x_encode_long(&x, 0);
    ei_x_encode_long(&x, 0);
    ei_x_encode_long(&x, 20000000);
    ei_x_encode_long(&x, 1500000);
    ei_x_encode_long(&x, 500000);
    ei_x_encode_boolean(&x, 0);
    ei_x_encode_empty_list(&x);
    send_x(c, &x);
}

static void send_velocity(struct child *c, long long ref, long long v)
{
    ei_x_buff x;
    ei_x_new_with_version(&x);
    ei_x_encode_tuple_header(&x, 2);
    ei_x_encode_longlong(&x, ref);
    ei_x_encode_tuple_header(&x, 2);
    ei_x_encode_atom(&x, "set_servos");
    ei_x_encode_list_header(&x, 1);
    ei_x_encode_tuple_header(&x, 2);
    ei_x_encode_atom(&x, "left");
    ei_x_encode_longlong(&x, v);
    ei_x_encode_empty_list(&x);
    send_x(c, &x);
}

static int finish(struct child *c)
{
    int status = 0;
    if (c->to >= 0)
        close(c->to);
    waitpid(c->pid, &status, 0);
    close(c->from);
    return WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
}

#define DUTY "class/pwm/pwmchip0/pwm0/duty_cycle"

/* A started port with servo "left" at full speed. */
static struct child running_servo(const char *root, struct port_opts *o)
{
    struct child c;

    fixture_pwm(root, 0, 0, true);
    port_opts_defaults(o);
    o->sysfs_root = root;
    c = start(o);
    CHECK_STR(next_term(&c, 5000), "{hello,1,sim}");
    send_servo(&c, 1);
    CHECK_STR(next_term(&c, 5000), "{reply,1,ok}");
    CHECK_STR(fixture_read(root, DUTY), "1500000");   /* servos start at neutral */
    send_velocity(&c, 2, 100);
    CHECK_STR(next_term(&c, 5000), "{reply,2,ok}");
    CHECK_STR(fixture_read(root, DUTY), "2000000");
    return c;
}

static void stdin_eof_puts_servos_to_neutral(void)
{
    const char *root = fixture_tmpdir();
    struct port_opts o;
    struct child c = running_servo(root, &o);

    close(c.to);
    c.to = -1;
    CHECK_STR(next_term(&c, 5000), "<closed>");
    CHECK_LL(finish(&c), 0);
    CHECK_STR(fixture_read(root, DUTY), "1500000");
}

static void bad_frame_goes_neutral_first_and_is_answered(void)
{
    const char *root = fixture_tmpdir();
    struct port_opts o;
    struct child c = running_servo(root, &o);
    ei_x_buff x;

    CHECK_LL(frame_write(c.to, "\x83\x68\x02garbage", 10), 0);
    CHECK_STR(next_term(&c, 5000), "{error,{bad_frame,not_a_term}}");
    CHECK_STR(fixture_read(root, DUTY), "1500000");
    send_velocity(&c, 3, 50);
    CHECK_STR(next_term(&c, 5000), "{reply,3,ok}");
    send_simple(&c, 4, "set_servos", 7);         /* well framed, ill formed */
    CHECK_STR(next_term(&c, 5000), "{reply,4,{error,{bad_request,set_servos}}}");
    CHECK_STR(fixture_read(root, DUTY), "1500000");
    CHECK_LL(frame_write(c.to, "", 0), 0);       /* an empty frame */
    CHECK_STR(next_term(&c, 5000), "{error,{bad_frame,not_a_term}}");
    ei_x_new_with_version(&x);
    ei_x_encode_tuple_header(&x, 2);
    ei_x_encode_long(&x, 5);
    ei_x_encode_atom(&x, "ping");
    send_x(&c, &x);
    CHECK_STR(next_term(&c, 5000), "{reply,5,pong}");
    CHECK_LL(finish(&c), 0);
}

static void watchdog_expiry_goes_neutral_then_reports(void)
{
    const char *root = fixture_tmpdir();
    struct port_opts o;
    struct child c = running_servo(root, &o);
    const char *t;

    send_simple(&c, 3, "configure_watchdog", 100);
    CHECK_STR(next_term(&c, 5000), "{reply,3,ok}");
    send_velocity(&c, 4, -100);
    CHECK_STR(next_term(&c, 5000), "{reply,4,ok}");
    CHECK_STR(fixture_read(root, DUTY), "1000000");
    t = next_term(&c, 5000);
    CHECK(strncmp(t, "{watchdog,", 10) == 0);
    CHECK_STR(fixture_read(root, DUTY), "1500000");
    CHECK_STR(next_term(&c, 300), "<timeout>");  /* once per silence */
    CHECK_LL(finish(&c), 0);
}

static void sim_adc_events_precede_the_reply(void)
{
    const char *root = fixture_tmpdir();
    struct port_opts o;
    struct child c;
    ei_x_buff x;
    const char *t;

    port_opts_defaults(&o);
    o.sysfs_root = root;
    c = start(&o);
    CHECK_STR(next_term(&c, 5000), "{hello,1,sim}");
    ei_x_new_with_version(&x);
    ei_x_encode_tuple_header(&x, 2);
    ei_x_encode_long(&x, 1);
    ei_x_encode_tuple_header(&x, 2);
    ei_x_encode_atom(&x, "configure_adc");
    ei_x_encode_list_header(&x, 1);
    ei_x_encode_tuple_header(&x, 4);
    ei_x_encode_long(&x, 2);
    ei_x_encode_atom(&x, "analog_threshold");
    ei_x_encode_long(&x, 2000);
    ei_x_encode_long(&x, 1500);
    ei_x_encode_empty_list(&x);
    send_x(&c, &x);
    CHECK_STR(next_term(&c, 5000), "{reply,1,ok}");
    ei_x_new_with_version(&x);
    ei_x_encode_tuple_header(&x, 2);
    ei_x_encode_long(&x, 2);
    ei_x_encode_tuple_header(&x, 3);
    ei_x_encode_atom(&x, "sim_adc");
    ei_x_encode_long(&x, 2);
    ei_x_encode_long(&x, 2500);
    send_x(&c, &x);
    t = next_term(&c, 5000);
    CHECK(strncmp(t, "{adc,2,1,", 9) == 0);
    CHECK_STR(next_term(&c, 5000), "{reply,2,ok}");
    CHECK_LL(finish(&c), 0);
}

static void sigterm_goes_neutral(void)
{
    const char *root = fixture_tmpdir();
    struct port_opts o;
    struct child c = running_servo(root, &o);

    kill(c.pid, SIGTERM);
    CHECK_STR(next_term(&c, 5000), "<closed>");
    CHECK_LL(finish(&c), 0);
    CHECK_STR(fixture_read(root, DUTY), "1500000");
}

static void unusable_backend_is_fatal_and_says_why(void)
{
    const char *root = fixture_tmpdir();
    char script[512], want[600];
    struct port_opts o;
    struct child c;

    snprintf(script, sizeof script, "%s/missing.script", root);
    port_opts_defaults(&o);
    o.sim_script = script;
    c = start(&o);
    snprintf(want, sizeof want, "{fatal,{sim_script,\"%s\",enoent}}", script);
    CHECK_STR(next_term(&c, 5000), want);
    CHECK_LL(finish(&c), 2);
}

const struct test_case port_tests[] = {
    TEST_CASE(stdin_eof_puts_servos_to_neutral),
    TEST_CASE(bad_frame_goes_neutral_first_and_is_answered),
    TEST_CASE(watchdog_expiry_goes_neutral_then_reports),
    TEST_CASE(sim_adc_events_precede_the_reply),
    TEST_CASE(sigterm_goes_neutral),
    TEST_CASE(unusable_backend_is_fatal_and_says_why),
    {NULL, NULL},
};
