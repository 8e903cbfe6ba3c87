/* See term.h. */
#include "term.h"

#include <math.h>
#include <stdint.h>
#include <string.h>

#include <lauxlib.h>

/* The external term format's tags (erts/emulator/beam/external.h). */
enum {
    T_NEW_FLOAT = 70, T_SMALL_INTEGER = 97, T_INTEGER = 98, T_ATOM = 100,
    T_SMALL_TUPLE = 104, T_LARGE_TUPLE = 105, T_NIL = 106, T_STRING = 107,
    T_LIST = 108, T_BINARY = 109, T_SMALL_BIG = 110, T_SMALL_ATOM = 115,
    T_MAP = 116, T_ATOM_UTF8 = 118, T_SMALL_ATOM_UTF8 = 119, T_VERSION = 131
};

void term_reader_init(struct term_reader *r, const unsigned char *b, size_t len)
{
    r->b = b;
    r->len = len;
    r->i = 0;
}

static bool need(const struct term_reader *r, size_t n)
{
    return n <= r->len && r->i <= r->len - n;
}

static bool u8(struct term_reader *r, uint32_t *v)
{
    if (!need(r, 1))
        return false;
    *v = r->b[r->i++];
    return true;
}

static bool u16(struct term_reader *r, uint32_t *v)
{
    if (!need(r, 2))
        return false;
    *v = ((uint32_t)r->b[r->i] << 8) | r->b[r->i + 1];
    r->i += 2;
    return true;
}

static bool u32(struct term_reader *r, uint32_t *v)
{
    if (!need(r, 4))
        return false;
    *v = ((uint32_t)r->b[r->i] << 24) | ((uint32_t)r->b[r->i + 1] << 16) |
         ((uint32_t)r->b[r->i + 2] << 8) | r->b[r->i + 3];
    r->i += 4;
    return true;
}

static int peek(const struct term_reader *r)
{
    return need(r, 1) ? r->b[r->i] : -1;
}

bool term_version(struct term_reader *r)
{
    uint32_t v;
    return u8(r, &v) && v == T_VERSION;
}

bool term_tuple(struct term_reader *r, size_t *arity)
{
    uint32_t tag, n;

    if (!u8(r, &tag))
        return false;
    if (tag == T_SMALL_TUPLE ? !u8(r, &n) : tag == T_LARGE_TUPLE ? !u32(r, &n) : true)
        return false;
    *arity = n;
    return true;
}

/* The text of an atom whose tag was just read: pointer and length. */
static bool atom_text(struct term_reader *r, uint32_t tag, const unsigned char **p, size_t *n)
{
    uint32_t len;
    bool ok;

    switch (tag) {
    case T_SMALL_ATOM: case T_SMALL_ATOM_UTF8: ok = u8(r, &len); break;
    case T_ATOM: case T_ATOM_UTF8: ok = u16(r, &len); break;
    default: return false;
    }
    if (!ok || !need(r, len))
        return false;
    *p = r->b + r->i;
    *n = len;
    r->i += len;
    return true;
}

bool term_atom(struct term_reader *r, char out[TERM_ATOM_MAX])
{
    uint32_t tag;
    const unsigned char *p;
    size_t n;

    if (!u8(r, &tag) || !atom_text(r, tag, &p, &n) || n >= TERM_ATOM_MAX)
        return false;
    memcpy(out, p, n);
    out[n] = '\0';
    return true;
}

/* An integer whose tag was just read, as a double too (bigs of up to 8
 * bytes; *fits is false when it does not fit a long long). */
static bool integer_body(struct term_reader *r, uint32_t tag, long long *v, double *d, bool *fits)
{
    uint32_t x, n, sign;
    unsigned long long mag = 0;

    *fits = true;
    switch (tag) {
    case T_SMALL_INTEGER:
        if (!u8(r, &x))
            return false;
        *v = x;
        break;
    case T_INTEGER:
        if (!u32(r, &x))
            return false;
        *v = (int32_t)x;
        break;
    case T_SMALL_BIG:
        if (!u8(r, &n) || !u8(r, &sign) || n > 8 || !need(r, n))
            return false;
        for (uint32_t k = 0; k < n; k++)
            mag |= (unsigned long long)r->b[r->i + k] << (8 * k);
        r->i += n;
        *d = sign ? -(double)mag : (double)mag;
        if (mag > (unsigned long long)INT64_MAX + (sign ? 1u : 0u)) {
            *fits = false;
            return true;
        }
        *v = sign ? (long long)(0 - mag) : (long long)mag;
        return true;
    default:
        return false;
    }
    *d = (double)*v;
    return true;
}

bool term_integer(struct term_reader *r, long long *v)
{
    uint32_t tag;
    double d;
    bool fits;

    return u8(r, &tag) && integer_body(r, tag, v, &d, &fits) && fits;
}

bool term_binary(struct term_reader *r, const unsigned char **p, size_t *n)
{
    uint32_t tag, len;

    if (!u8(r, &tag) || tag != T_BINARY || !u32(r, &len) || !need(r, len))
        return false;
    *p = r->b + r->i;
    *n = len;
    r->i += len;
    return true;
}

static bool skip_depth(struct term_reader *r, int depth)
{
    uint32_t tag, n;
    long long v;
    double d;
    bool fits;
    const unsigned char *p;
    size_t len;

    if (depth > TERM_MAX_DEPTH || !u8(r, &tag))
        return false;
    switch (tag) {
    case T_SMALL_INTEGER: case T_INTEGER: case T_SMALL_BIG:
        return integer_body(r, tag, &v, &d, &fits);
    case T_NEW_FLOAT:
        if (!need(r, 8))
            return false;
        r->i += 8;
        return true;
    case T_ATOM: case T_SMALL_ATOM: case T_ATOM_UTF8: case T_SMALL_ATOM_UTF8:
        return atom_text(r, tag, &p, &len);
    case T_NIL:
        return true;
    case T_STRING:
        if (!u16(r, &n) || !need(r, n))
            return false;
        r->i += n;
        return true;
    case T_BINARY:
        if (!u32(r, &n) || !need(r, n))
            return false;
        r->i += n;
        return true;
    case T_SMALL_TUPLE: case T_LARGE_TUPLE: case T_LIST: case T_MAP: {
        uint64_t count;
        if (tag == T_SMALL_TUPLE ? !u8(r, &n) : !u32(r, &n))
            return false;
        count = tag == T_MAP ? 2 * (uint64_t)n : n;
        if (count > r->len - r->i)        /* every term takes a byte at least */
            return false;
        for (uint64_t k = 0; k < count; k++)
            if (!skip_depth(r, depth + 1))
                return false;
        /* lists must be proper: [] as the tail */
        return tag != T_LIST || (u8(r, &n) && n == T_NIL);
    }
    default:
        return false;
    }
}

bool term_skip(struct term_reader *r)
{
    return skip_depth(r, 0);
}

static double be_double(const unsigned char *p)
{
    uint64_t bits = 0;
    double d;

    for (int k = 0; k < 8; k++)
        bits = (bits << 8) | p[k];
    memcpy(&d, &bits, sizeof d);
    return d;
}

static bool push_depth(lua_State *L, struct term_reader *r, int depth)
{
    uint32_t tag, n;
    long long v;
    double d;
    bool fits;
    const unsigned char *p;
    size_t len;

    if (depth > TERM_MAX_DEPTH || !u8(r, &tag))
        return false;
    luaL_checkstack(L, 4, "term nested too deeply");
    switch (tag) {
    case T_SMALL_INTEGER: case T_INTEGER: case T_SMALL_BIG:
        if (!integer_body(r, tag, &v, &d, &fits))
            return false;
        lua_pushnumber(L, fits ? (lua_Number)v : d);
        return true;
    case T_NEW_FLOAT:
        if (!need(r, 8))
            return false;
        lua_pushnumber(L, be_double(r->b + r->i));
        r->i += 8;
        return true;
    case T_ATOM: case T_SMALL_ATOM: case T_ATOM_UTF8: case T_SMALL_ATOM_UTF8:
        if (!atom_text(r, tag, &p, &len))
            return false;
        if (len == 3 && memcmp(p, "nil", 3) == 0)
            lua_pushnil(L);
        else if (len == 4 && memcmp(p, "true", 4) == 0)
            lua_pushboolean(L, 1);
        else if (len == 5 && memcmp(p, "false", 5) == 0)
            lua_pushboolean(L, 0);
        else
            lua_pushlstring(L, (const char *)p, len);
        return true;
    case T_NIL:
        lua_newtable(L);
        return true;
    case T_STRING:                      /* a list of small integers */
        if (!u16(r, &n) || !need(r, n))
            return false;
        lua_createtable(L, (int)n, 0);
        for (uint32_t k = 0; k < n; k++) {
            lua_pushnumber(L, r->b[r->i + k]);
            lua_rawseti(L, -2, (int)k + 1);
        }
        r->i += n;
        return true;
    case T_BINARY:
        if (!u32(r, &n) || !need(r, n))
            return false;
        lua_pushlstring(L, (const char *)r->b + r->i, n);
        r->i += n;
        return true;
    case T_SMALL_TUPLE: case T_LARGE_TUPLE: case T_LIST:
        if (tag == T_SMALL_TUPLE ? !u8(r, &n) : !u32(r, &n))
            return false;
        if (n > r->len - r->i)
            return false;
        lua_createtable(L, (int)n, 0);
        for (uint32_t k = 0; k < n; k++) {
            if (!push_depth(L, r, depth + 1)) {
                lua_pop(L, 1);
                return false;
            }
            lua_rawseti(L, -2, (int)k + 1);
        }
        if (tag == T_LIST && (!u8(r, &n) || n != T_NIL)) {
            lua_pop(L, 1);
            return false;
        }
        return true;
    case T_MAP:
        if (!u32(r, &n) || 2 * (uint64_t)n > r->len - r->i)
            return false;
        lua_createtable(L, 0, (int)n);
        for (uint32_t k = 0; k < n; k++) {
            if (!push_depth(L, r, depth + 1)) {
                lua_pop(L, 1);
                return false;
            }
            if (!push_depth(L, r, depth + 1)) {
                lua_pop(L, 2);
                return false;
            }
            /* a nil or NaN key cannot index a table: the pair is dropped */
            if (lua_isnil(L, -2) || (lua_type(L, -2) == LUA_TNUMBER &&
                                     lua_tonumber(L, -2) != lua_tonumber(L, -2)))
                lua_pop(L, 2);
            else
                lua_rawset(L, -3);
        }
        return true;
    default:
        return false;
    }
}

bool term_push(lua_State *L, struct term_reader *r)
{
    return push_depth(L, r, 0);
}

int term_push_values(lua_State *L, struct term_reader *r)
{
    int tag = peek(r);
    size_t n;

    if (tag == T_SMALL_TUPLE || tag == T_LARGE_TUPLE) {
        if (!term_tuple(r, &n) || n > r->len - r->i || n > TERM_MAX_VALUES)
            return -1;
        luaL_checkstack(L, (int)n + 4, "too many values");
        for (size_t k = 0; k < n; k++)
            if (!term_push(L, r)) {
                lua_pop(L, (int)k);
                return -1;
            }
        return (int)n;
    }
    return term_push(L, r) ? 1 : -1;
}

/* ---- Lua -> term ------------------------------------------------------- */

/* The length n of a table whose keys are exactly 1..n, else -1. */
static int array_length(lua_State *L, int idx)
{
    size_t n = lua_objlen(L, idx), count = 0;

    lua_pushnil(L);
    while (lua_next(L, idx) != 0) {
        lua_pop(L, 1);
        if (lua_type(L, -1) != LUA_TNUMBER) {
            lua_pop(L, 1);
            return -1;
        }
        lua_Number k = lua_tonumber(L, -1);
        if (k != floor(k) || k < 1 || k > (lua_Number)n) {
            lua_pop(L, 1);
            return -1;
        }
        count++;
    }
    return count == n && n <= 0x7fffffff ? (int)n : -1;
}

static void encode_depth(lua_State *L, int idx, ei_x_buff *x, int depth)
{
    if (depth > TERM_MAX_DEPTH)
        luaL_error(L, "value nested too deeply (or cyclic) to send");
    luaL_checkstack(L, 4, "value nested too deeply");
    switch (lua_type(L, idx)) {
    case LUA_TNIL:
        ei_x_encode_atom(x, "nil");
        return;
    case LUA_TBOOLEAN:
        ei_x_encode_boolean(x, lua_toboolean(L, idx));
        return;
    case LUA_TNUMBER: {
        lua_Number d = lua_tonumber(L, idx);
        if (!isfinite(d))
            luaL_error(L, "cannot send %s", d != d ? "nan" : "an infinite number");
        if (d == floor(d) && fabs(d) < 9.2e18)
            ei_x_encode_longlong(x, (long long)d);
        else
            ei_x_encode_double(x, d);
        return;
    }
    case LUA_TSTRING: {
        size_t n;
        const char *s = lua_tolstring(L, idx, &n);
        ei_x_encode_binary(x, s, (long)n);
        return;
    }
    case LUA_TTABLE: {
        int n = array_length(L, idx);
        if (n >= 0) {
            if (n > 0)
                ei_x_encode_list_header(x, n);
            for (int k = 1; k <= n; k++) {
                lua_rawgeti(L, idx, k);
                encode_depth(L, lua_gettop(L), x, depth + 1);
                lua_pop(L, 1);
            }
            ei_x_encode_empty_list(x);
            return;
        }
        long count = 0;
        lua_pushnil(L);
        while (lua_next(L, idx) != 0) {
            lua_pop(L, 1);
            count++;
        }
        ei_x_encode_map_header(x, count);
        lua_pushnil(L);
        while (lua_next(L, idx) != 0) {
            int top = lua_gettop(L);
            encode_depth(L, top - 1, x, depth + 1);
            encode_depth(L, top, x, depth + 1);
            lua_pop(L, 1);
        }
        return;
    }
    default:
        luaL_error(L, "cannot send a %s", luaL_typename(L, idx));
    }
}

void term_encode(lua_State *L, int idx, ei_x_buff *x)
{
    if (idx < 0 && idx > LUA_REGISTRYINDEX)
        idx = lua_gettop(L) + idx + 1;
    encode_depth(L, idx, x, 0);
}

void term_encode_values(lua_State *L, int idx, ei_x_buff *x)
{
    int n;

    if (idx < 0 && idx > LUA_REGISTRYINDEX)
        idx = lua_gettop(L) + idx + 1;
    if (lua_type(L, idx) != LUA_TTABLE || (n = array_length(L, idx)) < 0) {
        encode_depth(L, idx, x, 0);
        return;
    }
    if (n != 1)
        ei_x_encode_tuple_header(x, n);
    for (int k = 1; k <= n; k++) {
        lua_rawgeti(L, idx, k);
        encode_depth(L, lua_gettop(L), x, 1);
        lua_pop(L, 1);
    }
}
