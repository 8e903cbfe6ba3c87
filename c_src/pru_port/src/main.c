/*
 * pru_port: the Torocó hardware port program. Spawned by the Erlang
 * process toroco_pru_port with {packet, 2} on stdin/stdout; see
 * ../PROTOCOL.md for the frames and ../README.md for the options.
 */
#include <stdio.h>

#include <ei.h>

#include "port.h"

int main(int argc, char **argv)
{
    struct port_opts o;
    struct perr e;

    ei_init();
    port_opts_defaults(&o);
    perr_clear(&e);
    if (port_opts_parse(&o, argc, argv, &e) != 0) {
        fprintf(stderr, "pru_port: bad argument %s\n", e.text);
        fprintf(stderr, "usage: pru_port [--backend sim|pru] [--sysfs-root DIR] "
                        "[--gpiochip PATH] [--watchdog-ms N] [--sim-script FILE] "
                        "[--remoteproc DIR] [--firmware NAME] [--rpmsg-dev PATH] "
                        "[--rpmsg-wait-ms N]\n");
        return 2;
    }
    return port_run(&o, 0, 1);
}
