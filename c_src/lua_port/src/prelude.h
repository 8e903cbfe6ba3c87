/* prelude.lua, embedded by the Makefile (scripts/embed) as build/.../prelude.c. */
#ifndef LUA_PORT_PRELUDE_H
#define LUA_PORT_PRELUDE_H

#include <stddef.h>

extern const char prelude_lua[];
extern const size_t prelude_lua_len;

#endif
