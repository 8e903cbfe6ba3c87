/*
 * lua_port: the Lua behaviors of a Torocó node (SPEC §16). Spawned by the
 * Erlang process toroco_lua_port with {packet, 4} on stdin/stdout; see
 * ../PROTOCOL.md for the frames and ../README.md for why PUC Lua 5.1.
 */
#define _GNU_SOURCE
#include <sched.h>
#include <stdlib.h>

#include <ei.h>

#include "port.h"

/* argv[1], if given: microseconds to poll for the next request before
 * sleeping in read(2) (toroco_lua's env spin_us). */
int main(int argc, char **argv)
{
    long spin_us = argc > 1 ? strtol(argv[1], NULL, 10) : 0;

    ei_init();
#ifdef SCHED_BATCH
    {
        /* No wake-up preemption: a scheduler of the VM that writes a
         * request goes on with its work instead of being switched out for
         * this program on its own core. */
        struct sched_param sp = {0};
        (void)sched_setscheduler(0, SCHED_BATCH, &sp);
    }
#endif
    return port_run_spin(0, 1, spin_us < 0 || spin_us > 100000 ? 0 : spin_us);
}
