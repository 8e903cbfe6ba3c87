/*
 * Erlang terms <-> Lua values (SPEC §16), and the bounds-checked reader
 * every incoming frame goes through.
 *
 * ei's decoders take no buffer length, so nothing here uses them: the
 * reader below proves each byte it reads is inside the frame, and nesting
 * is bounded so that a hostile frame cannot blow the C or the Lua stack.
 *
 * In:  integers and floats -> numbers; binaries -> strings; true/false ->
 *      booleans; nil -> nil; other atoms -> strings; lists and tuples ->
 *      array tables; maps -> tables.
 * Out: numbers with an integral value -> integers, others -> floats;
 *      strings -> binaries; nil -> the atom nil; array tables (keys 1..n,
 *      the empty table included) -> lists; other tables -> maps.
 */
#ifndef LUA_PORT_TERM_H
#define LUA_PORT_TERM_H

#include <stdbool.h>
#include <stddef.h>

#include <ei.h>
#include <lua.h>

#define TERM_MAX_DEPTH 32
#define TERM_ATOM_MAX 256          /* bytes of an atom's UTF-8 text, plus NUL */
#define TERM_MAX_VALUES 200        /* values of one event (a tuple's elements) */

struct term_reader {
    const unsigned char *b;
    size_t len;
    size_t i;
};

void term_reader_init(struct term_reader *r, const unsigned char *b, size_t len);
/* The version byte 131. */
bool term_version(struct term_reader *r);
bool term_tuple(struct term_reader *r, size_t *arity);
/* An atom's text, NUL-terminated (atoms longer than TERM_ATOM_MAX-1 fail). */
bool term_atom(struct term_reader *r, char out[TERM_ATOM_MAX]);
/* An integer that fits a long long. */
bool term_integer(struct term_reader *r, long long *v);
/* A binary: a pointer into the frame and its length. */
bool term_binary(struct term_reader *r, const unsigned char **p, size_t *n);
/* Skips one whole term, checking it is complete, of a kind term_push
 * accepts, and no deeper than TERM_MAX_DEPTH. */
bool term_skip(struct term_reader *r);

/* Pushes one term as a Lua value; false (nothing pushed) if malformed. May
 * raise a Lua error (memory): call it in protected mode. */
bool term_push(lua_State *L, struct term_reader *r);
/* Pushes an event's values: a tuple's elements one by one, any other term
 * as one value. Returns how many were pushed, or -1 if malformed or more
 * than TERM_MAX_VALUES. */
int term_push_values(lua_State *L, struct term_reader *r);

/* Encodes the Lua value at idx. Raises a Lua error naming what cannot
 * cross (functions, userdata, threads, inf/nan, cycles and deep nests). */
void term_encode(lua_State *L, int idx, ei_x_buff *x);
/* Encodes the values of an event given as one Lua value: a pure array table
 * is the list of values (one -> the value, several -> a tuple, none -> {}),
 * anything else is one value. */
void term_encode_values(lua_State *L, int idx, ei_x_buff *x);

#endif
