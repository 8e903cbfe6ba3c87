/*
 * The port: the table of Lua states and the requests on them. One request
 * frame in, one reply frame out (PROTOCOL.md); port_handle is that step
 * alone, without file descriptors, for the tests and the fuzzer.
 */
#ifndef LUA_PORT_PORT_H
#define LUA_PORT_PORT_H

#include <stddef.h>

#include <ei.h>

#define PROTOCOL_VERSION 1
#define MAX_STATES 4096

struct port;

struct port *port_new(void);
void port_free(struct port *p);
/* Handles one frame; the reply (with version byte) is written into x, a
 * fresh buffer the caller frees. */
void port_handle(struct port *p, const unsigned char *frame, size_t len, ei_x_buff *x);
/* {bad_frame, too_big}: the answer to an oversized frame. */
void port_too_big(ei_x_buff *x, size_t len);
/* How many states are open. */
int port_states(const struct port *p);
/* Runs the loop on in_fd/out_fd until end of input; the exit code. */
int port_run(int in_fd, int out_fd);
/* The same, polling for input up to spin_us before each blocking read. */
int port_run_spin(int in_fd, int out_fd, long spin_us);

#endif
