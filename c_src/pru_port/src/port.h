/*
 * The port program's single poll() loop: frames from the Erlang owner on
 * in_fd, replies and events to out_fd, the backend's device, the button
 * line and the timers (watchdog, sim script, debounce) in one place.
 */
#ifndef PORT_H
#define PORT_H

#include "backend.h"

void port_opts_defaults(struct port_opts *o);
/* Parses the command line into o (strings point into argv). */
int port_opts_parse(struct port_opts *o, int argc, char **argv, struct perr *e);

/* Runs until end of input, an I/O failure on the pipe or SIGTERM/SIGINT/
 * SIGHUP; the servos are at neutral when it returns. 0 on a clean end. */
int port_run(const struct port_opts *o, int in_fd, int out_fd);

/* CLOCK_MONOTONIC in milliseconds: the timestamps of events. */
long long clock_ms(void);

#endif
