/* The sim backend's script and feed; the pru backend against a fake
 * remoteproc tree and a pseudo-terminal standing in for the rpmsg device. */
#define _XOPEN_SOURCE 700
#include "test.h"

#include <fcntl.h>
#include <poll.h>
#include <stdlib.h>
#include <termios.h>
#include <unistd.h>

#include "backend.h"
#include "backend_sim.h"
#include "port.h"
#include "pru_msg.h"

struct seen {
    int n;
    unsigned ch[32], value[32];
    long long t[32];
    int buttons[32], nb;
    int faults;
};

static void seen_adc(void *ctx, unsigned ch, unsigned value, long long now)
{
    struct seen *s = ctx;
    if (s->n < 32) {
        s->ch[s->n] = ch;
        s->value[s->n] = value;
        s->t[s->n] = now;
    }
    s->n++;
}

static void seen_button(void *ctx, enum button_edge edge, long long now)
{
    struct seen *s = ctx;
    (void)now;
    if (s->nb < 32)
        s->buttons[s->nb] = edge;
    s->nb++;
}

static void seen_fault(void *ctx, const struct perr *e)
{
    struct seen *s = ctx;
    (void)e;
    s->faults++;
}

static void script_parses_and_names_bad_lines(void)
{
    const char *root = fixture_tmpdir();
    char path[512], where[600];
    struct sim_step *steps;
    int n;
    struct perr e;

    snprintf(path, sizeof path, "%s/ok.script", root);
    fixture_write(root, "ok.script", "# IR left\n\n10 0 100\n  5 1 4095\n0 button 1\n");
    perr_clear(&e);
    CHECK_LL(sim_script_load(path, &steps, &n, &e), 0);
    CHECK_LL(n, 3);
    CHECK_LL(steps[0].after_ms, 10);
    CHECK_LL(steps[1].channel, 1);
    CHECK_LL(steps[1].value, 4095);
    CHECK_LL(steps[2].kind, SIM_STEP_BUTTON);
    free(steps);

    snprintf(path, sizeof path, "%s/bad.script", root);
    fixture_write(root, "bad.script", "10 0 100\n10 0 100 7\n");
    CHECK_LL(sim_script_load(path, &steps, &n, &e), -1);
    snprintf(where, sizeof where, "%s:2", path);
    CHECK_STR(e.reason, "sim_script");
    CHECK_STR(e.text, where);
    CHECK(steps == NULL);

    snprintf(path, sizeof path, "%s/none.script", root);
    CHECK_LL(sim_script_load(path, &steps, &n, &e), -1);
    CHECK_STR(errno_atom(e.errnum), "enoent");
}

static void sim_plays_its_script_through_the_filter(void)
{
    const char *root = fixture_tmpdir();
    char path[512];
    struct port_opts o;
    struct adc_bank adc;
    struct button btn;
    struct backend b;
    struct seen seen = {0};
    struct backend_sink sink = {&seen, seen_adc, seen_button, seen_fault};
    struct adc_config cfg[1] = {{.channel = 0, .mode = ADC_THRESHOLD, .high = 2000, .low = 1500}};
    struct perr e;

    snprintf(path, sizeof path, "%s/s", root);
    /* a crossing up, noise, a crossing down, an unconfigured channel, the button */
    fixture_write(root, "s", "10 0 1000\n10 0 2500\n10 0 1600\n10 0 1999\n10 0 1400\n"
                             "10 3 7\n10 button 1\n");
    port_opts_defaults(&o);
    o.sim_script = path;
    adc_init(&adc);
    button_init(&btn);
    perr_clear(&e);
    CHECK_LL(adc_configure(&adc, cfg, 1, &e), 0);
    b = (struct backend){.ops = &backend_sim_ops, .opts = &o, .adc = &adc, .button = &btn};
    CHECK_LL(b.ops->open(&b, 1000, &e), 0);
    CHECK_LL(b.ops->configure_button(&b, 0, false, 0, &e), 0);
    CHECK_LL(b.ops->fd(&b), -1);
    CHECK_LL(b.ops->timeout(&b, 1000), 10);
    b.ops->run(&b, false, 1009, &sink);
    CHECK_LL(seen.n, 0);
    b.ops->run(&b, false, 1010, &sink);
    CHECK_LL(seen.n, 1);
    CHECK_LL(seen.value[0], 0);
    CHECK_LL(b.ops->timeout(&b, 1010), 10);
    b.ops->run(&b, false, 2000, &sink);           /* late: everything due runs */
    CHECK_LL(seen.n, 3);
    CHECK_LL(seen.value[1], 1);
    CHECK_LL(seen.value[2], 0);
    CHECK_LL(seen.nb, 1);
    CHECK_LL(seen.buttons[0], BUTTON_PRESSED);
    CHECK_LL(b.ops->timeout(&b, 2000), -1);
    /* direct samples */
    CHECK_LL(b.ops->sim_adc(&b, 0, 3000, 2001, &sink, &e), 0);
    CHECK_LL(seen.n, 4);
    CHECK_LL(b.ops->sim_adc(&b, 3, 3000, 2001, &sink, &e), -1);
    CHECK_STR(e.reason, "unconfigured_channel");
    CHECK_LL(b.ops->sim_adc(&b, 0, 4096, 2001, &sink, &e), -1);
    CHECK_STR(e.reason, "bad_adc_value");
    CHECK_LL(b.ops->sim_button(&b, 2, 2001, &sink, &e), -1);
    CHECK_STR(e.reason, "bad_level");
    b.ops->close(&b);
}

/* A pty in raw mode: the master is the "PRU", the slave path the device. */
static int open_fake_rpmsg(char *slave_path, size_t cap, int *slave_keep)
{
    int master = posix_openpt(O_RDWR | O_NOCTTY);
    struct termios t;

    if (master < 0 || grantpt(master) != 0 || unlockpt(master) != 0)
        return -1;
    snprintf(slave_path, cap, "%s", ptsname(master));
    *slave_keep = open(slave_path, O_RDWR | O_NOCTTY);
    if (*slave_keep < 0 || tcgetattr(*slave_keep, &t) != 0)
        return -1;
    cfmakeraw(&t);
    tcsetattr(*slave_keep, TCSANOW, &t);
    return master;
}

static int read_full(int fd, uint8_t *buf, size_t len)
{
    size_t got = 0;
    while (got < len) {
        struct pollfd p = {.fd = fd, .events = POLLIN};
        ssize_t n;
        if (poll(&p, 1, 2000) <= 0)
            return -1;
        n = read(fd, buf + got, len - got);
        if (n <= 0)
            return -1;
        got += (size_t)n;
    }
    return 0;
}

static void pru_loads_firmware_and_speaks_rpmsg(void)
{
    const char *root = fixture_tmpdir();
    char dev[128];
    int keep = -1, master = open_fake_rpmsg(dev, sizeof dev, &keep);
    struct port_opts o;
    struct adc_bank adc;
    struct button btn;
    struct backend b;
    struct seen seen = {0};
    struct backend_sink sink = {&seen, seen_adc, seen_button, seen_fault};
    struct adc_config cfg[2] = {{.channel = 0, .mode = ADC_THRESHOLD, .high = 2000, .low = 1500},
                                {.channel = 1, .mode = ADC_ANALOG}};
    uint8_t msg[PRU_MSG_SIZE * ADC_CHANNELS];
    struct pru_msg m;
    struct perr e;

    CHECK(master >= 0);
    if (master < 0)
        return;
    fixture_write(root, "class/remoteproc/remoteproc1/state", "running\n");
    fixture_touch(root, "class/remoteproc/remoteproc1/firmware");
    port_opts_defaults(&o);
    o.backend = "pru";
    o.sysfs_root = root;
    o.firmware = "am335x-pru0-toroco-fw";
    o.rpmsg_dev = dev;
    adc_init(&adc);
    button_init(&btn);
    b = (struct backend){.ops = &backend_pru_ops, .opts = &o, .adc = &adc, .button = &btn};
    perr_clear(&e);
    CHECK_LL(b.ops->open(&b, 0, &e), 0);
    CHECK(e.reason == NULL);
    CHECK_STR(fixture_read(root, "class/remoteproc/remoteproc1/firmware"), "am335x-pru0-toroco-fw");
    CHECK_STR(fixture_read(root, "class/remoteproc/remoteproc1/state"), "start");
    CHECK(b.ops->fd(&b) >= 0);
    CHECK_LL(read_full(master, msg, PRU_MSG_SIZE), 0);
    pru_msg_unpack(msg, &m);
    CHECK_LL(m.type, PRU_MSG_HELLO);

    CHECK_LL(adc_configure(&adc, cfg, 2, &e), 0);
    CHECK_LL(b.ops->configure_adc(&b, &e), 0);
    CHECK_LL(read_full(master, msg, sizeof msg), 0);
    pru_msg_unpack(msg, &m);
    CHECK_LL(m.type, PRU_MSG_CONFIG);
    CHECK_LL(m.channel, 0);
    CHECK_LL(m.mode, ADC_THRESHOLD);
    CHECK_LL(m.a, 2000);
    CHECK_LL(m.b, 1500);
    pru_msg_unpack(msg + PRU_MSG_SIZE, &m);
    CHECK_LL(m.mode, ADC_ANALOG);
    pru_msg_unpack(msg + 7 * PRU_MSG_SIZE, &m);
    CHECK_LL(m.channel, 7);
    CHECK_LL(m.mode, ADC_OFF);

    /* two changes, one for a channel the host never asked for */
    {
        struct pru_msg up = {.type = PRU_MSG_ADC_CHANGE, .channel = 0, .a = 1};
        struct pru_msg stray = {.type = PRU_MSG_ADC_CHANGE, .channel = 5, .a = 9};
        uint8_t out[2 * PRU_MSG_SIZE];
        struct pollfd p = {.fd = b.ops->fd(&b), .events = POLLIN};
        pru_msg_pack(&up, out);
        pru_msg_pack(&stray, out + PRU_MSG_SIZE);
        CHECK_LL(write(master, out, sizeof out), sizeof out);
        for (int i = 0; i < 10 && seen.n == 0; i++) {
            CHECK(poll(&p, 1, 2000) == 1);
            b.ops->run(&b, true, 42, &sink);
        }
        CHECK_LL(seen.n, 1);
        CHECK_LL(seen.ch[0], 0);
        CHECK_LL(seen.value[0], 1);
        CHECK_LL(seen.t[0], 42);
    }
    CHECK_LL(b.ops->sim_adc(&b, 0, 1, 0, &sink, &e), -1);
    CHECK_STR(e.reason, "not_simulated");
    b.ops->close(&b);
    close(keep);
    close(master);
}

static void pru_without_device_runs_degraded(void)
{
    const char *root = fixture_tmpdir();
    char dev[512];
    struct port_opts o;
    struct adc_bank adc;
    struct button btn;
    struct backend b;
    struct perr e;

    snprintf(dev, sizeof dev, "%s/rpmsg_pru30", root);
    port_opts_defaults(&o);
    o.backend = "pru";
    o.rpmsg_dev = dev;
    o.rpmsg_wait_ms = 40;
    adc_init(&adc);
    button_init(&btn);
    b = (struct backend){.ops = &backend_pru_ops, .opts = &o, .adc = &adc, .button = &btn};
    perr_clear(&e);
    CHECK_LL(b.ops->open(&b, 0, &e), 0);
    CHECK_STR(e.reason, "rpmsg");
    CHECK_STR(e.text, dev);
    CHECK_LL(b.ops->fd(&b), -1);
    CHECK_LL(b.ops->configure_adc(&b, &e), -1);
    CHECK_STR(e.reason, "rpmsg");
    b.ops->close(&b);
}

const struct test_case backend_tests[] = {
    TEST_CASE(script_parses_and_names_bad_lines),
    TEST_CASE(sim_plays_its_script_through_the_filter),
    TEST_CASE(pru_loads_firmware_and_speaks_rpmsg),
    TEST_CASE(pru_without_device_runs_degraded),
    {NULL, NULL},
};
