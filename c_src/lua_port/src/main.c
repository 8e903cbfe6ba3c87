/*
 * lua_port: the Lua behaviors of a Torocó node (SPEC §16). Spawned by the
 * Erlang process toroco_lua_port with {packet, 4} on stdin/stdout; see
 * ../PROTOCOL.md for the frames and ../README.md for why PUC Lua 5.1.
 */
#include <stdlib.h>

#include <ei.h>

#include "port.h"

/* argv[1], if given: microseconds to poll for the next request before
 * sleeping in read(2) (toroco_lua's env spin_us). */
int main(int argc, char **argv)
{
    long spin_us = argc > 1 ? strtol(argv[1], NULL, 10) : 0;

    ei_init();
    return port_run_spin(0, 1, spin_us < 0 || spin_us > 100000 ? 0 : spin_us);
}
