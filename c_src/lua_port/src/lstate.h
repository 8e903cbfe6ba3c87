/*
 * One Lua state, hosting one or more Lua behaviors (slots): slot 0 runs
 * the behavior's file; the others are the behaviors its code added with
 * inline functions (toroco.add_behavior) or its converters
 * (toroco.configure_polling). One Lua state is a lua_State with its own allocator (the memory
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
    long long id;                /* the id it was opened with: attach finds it by this */
    int refs;                    /* slots held: the state lives while any is */
    unsigned char *held;         /* slot -> held */
    int held_cap;
    bool dead;                   /* out of memory: every slot's next request stops */
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
/* As lstate_input, for the behavior of slot `slot'. */
bool lstate_input_slot(struct lstate *s, int slot, const char *input, struct term_reader *value,
                       long long now_ms);
/* A timer the state asked for fired. */
void lstate_timer(struct lstate *s, long long task, long long seq, long long now_ms);
/* Starts the tasks of slot `slot' (a behavior the state's code added):
 * false, and nothing ran, if the state made no such slot. */
bool lstate_attach(struct lstate *s, int slot, long long now_ms);
/* Ends the tasks of slot `slot'; with `release', the slot is no longer
 * held (its behavior is gone for good). Returns the slots still held. */
int lstate_detach(struct lstate *s, int slot, bool release);
/* After a failure that ended one slot's behavior (an error, the budget):
 * the state goes on for its other slots. False if the state cannot (its
 * memory cap). */
bool lstate_recover(struct lstate *s);
/* Encodes what the tasks wait for: [{Task, Input | false, TimerPending}]. */
void lstate_waits(struct lstate *s, ei_x_buff *x);
/* As lstate_waits, the tasks of one slot. */
void lstate_waits_slot(struct lstate *s, int slot, ei_x_buff *x);
/* The actions since the last take, as a list term appended to x; clears them. */
void lstate_take_actions(struct lstate *s, ei_x_buff *x);
/* {lua_error, File, Line, Msg} or {lua_limit, File, budget | memory}. */
void lstate_encode_failure(const struct lstate *s, ei_x_buff *x);
void lstate_close(struct lstate *s);

#endif
