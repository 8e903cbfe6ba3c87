/*
 * fake_pru: the PRU firmware's side of the rpmsg channel, on the host, for
 * the emulated board (scripts/board-emulate). It stands where the kernel's
 * /dev/rpmsg_pru30 would be: a pseudo-terminal in raw mode, whose other end
 * is linked at the given path, carrying the same 8-byte records
 * (src/pru_msg.h). Like firmware/main.c it waits for HELLO, applies CONFIG
 * with adc_filter_configure and posts ADC_CHANGE when adc_filter_sample
 * says a channel's value changed: the same filter code, fed with raw
 * samples read from a FIFO instead of the AM335x ADC.
 *
 *   fake_pru LINK FIFO     LINK: where the rpmsg device is looked for
 *                          FIFO: lines "CHANNEL RAW" (0..7, 0..4095)
 *
 * It logs what it sees on stderr and runs until killed.
 */
#define _GNU_SOURCE
#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <termios.h>
#include <unistd.h>

#include "../src/adc_filter.h"
#include "../src/pru_msg.h"

static struct adc_channel channels[ADC_CHANNELS];
static int hello;

static void post(int master, uint8_t ch, uint16_t value)
{
    struct pru_msg m = {.type = PRU_MSG_ADC_CHANGE, .channel = ch, .a = value};
    uint8_t out[PRU_MSG_SIZE];

    pru_msg_pack(&m, out);
    if (write(master, out, sizeof out) != (ssize_t)sizeof out)
        fprintf(stderr, "fake_pru: write: %s\n", strerror(errno));
    else
        fprintf(stderr, "fake_pru: ADC_CHANGE channel %u value %u\n", ch, value);
}

static void from_host(int master, const uint8_t rec[PRU_MSG_SIZE])
{
    struct pru_msg m;

    pru_msg_unpack(rec, &m);
    if (m.type == PRU_MSG_HELLO) {
        hello = 1;
        fprintf(stderr, "fake_pru: HELLO\n");
    } else if (m.type == PRU_MSG_CONFIG && m.channel < ADC_CHANNELS) {
        bool ok = adc_filter_configure(&channels[m.channel], m.mode, m.a, m.b);
        if (m.mode != ADC_OFF)
            fprintf(stderr, "fake_pru: CONFIG channel %u mode %u high %u low %u%s\n",
                    m.channel, m.mode, m.a, m.b, ok ? "" : " (refused)");
    }
    (void)master;
}

static void sample(int master, const char *line)
{
    unsigned ch, raw;
    uint16_t out;

    if (sscanf(line, "%u %u", &ch, &raw) != 2 || ch >= ADC_CHANNELS || raw > ADC_MAX_RAW) {
        fprintf(stderr, "fake_pru: ignored sample line: %s", line);
        return;
    }
    fprintf(stderr, "fake_pru: sample channel %u raw %u\n", ch, raw);
    /* like the firmware: nothing is sampled before the host said hello */
    if (hello && adc_filter_sample(&channels[ch], (uint16_t)raw, &out))
        post(master, (uint8_t)ch, out);
}

int main(int argc, char **argv)
{
    int master, slave, fifo;
    struct termios t;
    uint8_t rx[PRU_MSG_SIZE * 16];
    size_t rx_len = 0;
    char lines[512];
    size_t lines_len = 0;

    if (argc != 3) {
        fprintf(stderr, "usage: fake_pru LINK FIFO\n");
        return 2;
    }
    master = posix_openpt(O_RDWR | O_NOCTTY);
    if (master < 0 || grantpt(master) != 0 || unlockpt(master) != 0) {
        perror("fake_pru: pty");
        return 1;
    }
    /* Held open so that the host closing and reopening the device is not a hangup. */
    slave = open(ptsname(master), O_RDWR | O_NOCTTY);
    if (slave < 0 || tcgetattr(slave, &t) != 0) {
        perror("fake_pru: pty slave");
        return 1;
    }
    cfmakeraw(&t);
    tcsetattr(slave, TCSANOW, &t);
    unlink(argv[1]);
    if (symlink(ptsname(master), argv[1]) != 0) {
        perror("fake_pru: symlink");
        return 1;
    }
    fifo = open(argv[2], O_RDWR | O_NONBLOCK);   /* RDWR: never EOF between writers */
    if (fifo < 0) {
        perror("fake_pru: fifo");
        return 1;
    }
    fprintf(stderr, "fake_pru: rpmsg at %s -> %s, samples from %s\n", argv[1], ptsname(master),
            argv[2]);
    for (;;) {
        struct pollfd p[2] = {{.fd = master, .events = POLLIN}, {.fd = fifo, .events = POLLIN}};
        if (poll(p, 2, -1) < 0 && errno != EINTR)
            return 1;
        if (p[0].revents & POLLIN) {
            ssize_t n = read(master, rx + rx_len, sizeof rx - rx_len);
            if (n > 0) {
                size_t off = 0;
                rx_len += (size_t)n;
                for (; rx_len - off >= PRU_MSG_SIZE; off += PRU_MSG_SIZE)
                    from_host(master, rx + off);
                memmove(rx, rx + off, rx_len - off);
                rx_len -= off;
            }
        }
        if (p[1].revents & POLLIN) {
            ssize_t n = read(fifo, lines + lines_len, sizeof lines - 1 - lines_len);
            char *nl;
            if (n > 0)
                lines_len += (size_t)n;
            lines[lines_len] = '\0';
            while ((nl = strchr(lines, '\n')) != NULL) {
                size_t len = (size_t)(nl - lines) + 1;
                char line[128];
                snprintf(line, sizeof line, "%.*s", (int)len, lines);
                sample(master, line);
                memmove(lines, lines + len, lines_len - len + 1);
                lines_len -= len;
            }
            if (lines_len == sizeof lines - 1)
                lines_len = 0;                   /* a line too long: dropped */
        }
    }
}
