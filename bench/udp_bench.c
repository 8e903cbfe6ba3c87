/* External benchmark peer: a separate OS process that sends timestamped
 * events to the runtime's UDP link and receives them back from the other
 * link, as the thesis' external test did.
 *
 *   udp_bench IN_PORT OUT_PORT INTERVAL_MS COUNT
 *
 * Sends COUNT datagrams {"output":"event","value":[SEQ,T_NS]} to
 * 127.0.0.1:IN_PORT, one every INTERVAL_MS (absolute schedule, may be
 * fractional), while receiving {"input":"in","value":[SEQ,T_NS]} on
 * 127.0.0.1:OUT_PORT. Prints "lat NS" per event received, then "lost N".
 */
#define _GNU_SOURCE
#include <arpa/inet.h>
#include <poll.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

static int64_t now_ns(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * 1000000000LL + ts.tv_nsec;
}

static int udp_socket(int port) {
    int s = socket(AF_INET, SOCK_DGRAM, 0);
    if (s < 0) { perror("socket"); exit(2); }
    int buf = 4 << 20;
    setsockopt(s, SOL_SOCKET, SO_RCVBUF, &buf, sizeof buf);
    struct sockaddr_in a = {.sin_family = AF_INET, .sin_port = htons(port)};
    a.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    if (port && bind(s, (struct sockaddr *)&a, sizeof a) < 0) { perror("bind"); exit(2); }
    return s;
}

/* Finds "value":[SEQ,T] in a datagram. */
static int parse(const char *b, long *seq, int64_t *t) {
    const char *v = strstr(b, "\"value\"");
    if (!v) return 0;
    v = strchr(v, '[');
    if (!v) return 0;
    long long tt;
    if (sscanf(v, "[%ld,%lld]", seq, &tt) != 2) return 0;
    *t = tt;
    return 1;
}

static void drain(int rx, int64_t *lat, char *got, long count, long *received, int timeout_ms) {
    struct pollfd p = {.fd = rx, .events = POLLIN};
    char buf[2048];
    while (poll(&p, 1, timeout_ms) > 0) {
        ssize_t n = recv(rx, buf, sizeof buf - 1, 0);
        if (n <= 0) break;
        buf[n] = 0;
        long seq; int64_t t;
        if (parse(buf, &seq, &t) && seq >= 1 && seq <= count && !got[seq]) {
            got[seq] = 1;
            lat[seq] = now_ns() - t;
            (*received)++;
        }
        timeout_ms = 0;
    }
}

int main(int argc, char **argv) {
    if (argc != 5) {
        fprintf(stderr, "usage: udp_bench IN_PORT OUT_PORT INTERVAL_MS COUNT\n");
        return 2;
    }
    int in_port = atoi(argv[1]), out_port = atoi(argv[2]);
    double interval_ms = atof(argv[3]);
    long count = atol(argv[4]);
    int tx = udp_socket(0), rx = udp_socket(out_port);
    struct sockaddr_in to = {.sin_family = AF_INET, .sin_port = htons(in_port)};
    to.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    int64_t *lat = calloc(count + 1, sizeof *lat);
    char *got = calloc(count + 1, 1);
    long received = 0;
    int64_t start = now_ns(), step = (int64_t)(interval_ms * 1e6);
    for (long seq = 1; seq <= count; seq++) {
        int64_t due = start + (seq - 1) * step;
        for (;;) {                      /* receive until the next send is due */
            int64_t left = due - now_ns();
            if (left <= 0) break;
            drain(rx, lat, got, count, &received, left > 1000000 ? (int)(left / 1000000) : 0);
        }
        char msg[128];
        int n = snprintf(msg, sizeof msg, "{\"output\":\"event\",\"value\":[%ld,%lld]}",
                         seq, (long long)now_ns());
        sendto(tx, msg, n, 0, (struct sockaddr *)&to, sizeof to);
    }
    int64_t end = now_ns() + 1000000000LL;      /* stragglers: one more second */
    while (received < count && now_ns() < end) drain(rx, lat, got, count, &received, 10);
    for (long s = 1; s <= count; s++)
        if (got[s]) printf("lat %lld\n", (long long)lat[s]);
    printf("lost %ld\n", count - received);
    return 0;
}
