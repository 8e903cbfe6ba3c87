/*
 * lua_port: the Lua behaviors of a Torocó node (SPEC §16). Spawned by the
 * Erlang process toroco_lua_port with {packet, 4} on stdin/stdout; see
 * ../PROTOCOL.md for the frames and ../README.md for why PUC Lua 5.1.
 */
#include <ei.h>

#include "port.h"

int main(void)
{
    ei_init();
    return port_run(0, 1);
}
