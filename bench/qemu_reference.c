/* A C reference for `make board-bench' (scripts/board-emulate): the same
 * integer work built for this machine and for armhf, the latter run under
 * qemu-arm, tells qemu's cost on compiled code from its cost on the Erlang
 * interpreter. Sorting, hashing and a small switch-dispatched stack machine
 * (an interpreter's shape); prints a checksum so nothing is optimised away. */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>

static uint32_t hash(uint32_t x)
{
    x ^= x >> 16; x *= 0x7feb352dU;
    x ^= x >> 15; x *= 0x846ca68bU;
    x ^= x >> 16;
    return x;
}

static int cmp(const void *a, const void *b)
{
    uint32_t x = *(const uint32_t *)a, y = *(const uint32_t *)b;
    return x < y ? -1 : x > y;
}

static uint32_t machine(const unsigned char *code, int n, uint32_t acc)
{
    uint32_t stack[64];
    int sp = 0, pc = 0;
    for (int steps = 0; steps < 4000000; steps++) {
        unsigned char op = code[pc];
        pc = (pc + 1) % n;
        switch (op & 7) {
        case 0: stack[sp++ & 63] = acc; break;
        case 1: acc += stack[--sp & 63]; break;
        case 2: acc ^= acc << 3; break;
        case 3: acc = hash(acc); break;
        case 4: acc += op; break;
        case 5: if (acc & 1) pc = (pc + 3) % n; break;
        case 6: acc = acc * 33 + 7; break;
        default: acc -= (uint32_t)sp;
        }
    }
    return acc;
}

int main(void)
{
    enum { N = 200000, CODE = 97 };
    uint32_t *a = malloc(N * sizeof *a), sum = 0;
    unsigned char code[CODE];
    if (!a) return 1;
    for (int i = 0; i < CODE; i++) code[i] = (unsigned char)hash((uint32_t)i);
    for (int r = 0; r < 10; r++) {
        for (int i = 0; i < N; i++) a[i] = hash((uint32_t)(i + r * N));
        qsort(a, N, sizeof *a, cmp);
        sum += a[N / 2];
        sum += machine(code, CODE, sum);
    }
    printf("%u\n", sum);
    free(a);
    return 0;
}
