/* Reference for the "Lua behaviors" section: the cheapest exchange a Lua
 * activation can cost, with no Lua and no VM. A parent and a child process
 * pass one byte back and forth over two pipes, as the runtime and lua_port
 * pass an event and its reply; each round trip wakes the child and then the
 * parent, which is what every activation of a Lua behavior pays at least.
 *
 *   pipe_pingpong COUNT
 *
 * Prints "rtt NS" for each of COUNT round trips (after 1000 not counted).
 */
#define _GNU_SOURCE
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

static int64_t now_ns(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (int64_t)ts.tv_sec * 1000000000LL + ts.tv_nsec;
}

static void must(int ok, const char *what) {
    if (!ok) { perror(what); exit(2); }
}

int main(int argc, char **argv) {
    long count = argc > 1 ? atol(argv[1]) : 0;
    if (count <= 0) {
        fprintf(stderr, "usage: pipe_pingpong COUNT\n");
        return 2;
    }
    int to_child[2], to_parent[2];
    must(pipe(to_child) == 0 && pipe(to_parent) == 0, "pipe");
    pid_t child = fork();
    must(child >= 0, "fork");
    char c = 'x';
    if (child == 0) {
        close(to_child[1]);
        close(to_parent[0]);
        while (read(to_child[0], &c, 1) == 1)
            must(write(to_parent[1], &c, 1) == 1, "write");
        _exit(0);
    }
    close(to_child[0]);
    close(to_parent[1]);
    for (long i = -1000; i < count; i++) {
        int64_t t0 = now_ns();
        must(write(to_child[1], &c, 1) == 1, "write");
        must(read(to_parent[0], &c, 1) == 1, "read");
        if (i >= 0) printf("rtt %lld\n", (long long)(now_ns() - t0));
    }
    close(to_child[1]);
    waitpid(child, NULL, 0);
    return 0;
}
