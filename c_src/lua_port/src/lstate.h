/*
 * One Lua behavior's state: a lua_State with its own allocator (the memory
 * cap), a count hook (the instruction budget of one activation), the
 * sandboxed Torocó API of prelude.lua, and the actions its last activation
 * produced. Nothing here reads a clock or touches a file descriptor but the
 * program's own files: the caller passes the time in, takes the actions out.
 */
#ifndef LUA_PORT_LSTATE_H
#define LUA_PORT_LSTATE_H

#include <limits.h>
#include <stdbool.h>
#include <stddef.h>

#include <ei.h>
#include <lua.h>

#include "term.h"

enum lstate_limit { LIMIT_NONE, LIMIT_BUDGET, LIMIT_MEMORY };

struct lstate_opts {
    const char *file;            /* the behavior's file, as the owner names it */
    const char *dir;             /* the program's folder: require finds modules here */
    unsigned long budget;        /* instructions per activation */
    size_t mem_cap;              /* bytes */
};

struct lstate {
    long long id;
    lua_State *L;
    size_t mem, mem_cap;
    unsigned long budget, used;
    bool ready;                  /* the prelude ran: limits count from here */
    enum lstate_limit limit;
    bool failed;                 /* stopped: error or limit; the state is done */
    char fail_file[PATH_MAX];
    long fail_line;
    char fail_msg[512];
    char file[PATH_MAX];         /* the chunk name of the behavior's file (relative to dir) */
    char dir[PATH_MAX];
    long long now_ms;
    int entry_ref;
    ei_x_buff actions;           /* list elements, each after a 1-element list header */
    int n_actions;
    ei_x_buff scratch;           /* one value being encoded (a raise leaves it here) */
};

/* A new state running `opts->file' (params pushed from `params', a map term,
 * or NULL). Returns NULL only when out of host memory; a file that fails is
 * a state with `failed' set. */
struct lstate *lstate_open(long long id, const struct lstate_opts *opts,
                           struct term_reader *params, long long now_ms);
/* An input's arrival: `value' is the event's term (a tuple: several values).
 * false, and nothing ran, if the value cannot be taken (a tuple of more than
 * TERM_MAX_VALUES values). */
bool lstate_input(struct lstate *s, const char *input, struct term_reader *value,
                  long long now_ms);
/* A timer the state asked for fired. */
void lstate_timer(struct lstate *s, long long task, long long seq, long long now_ms);
/* Encodes what the tasks wait for: [{Task, Input | false, TimerPending}]. */
void lstate_waits(struct lstate *s, ei_x_buff *x);
/* The actions since the last take, as a list term appended to x; clears them. */
void lstate_take_actions(struct lstate *s, ei_x_buff *x);
/* {lua_error, File, Line, Msg} or {lua_limit, File, budget | memory}. */
void lstate_encode_failure(const struct lstate *s, ei_x_buff *x);
void lstate_close(struct lstate *s);

#endif
