/* Terms <-> Lua values (SPEC §16) and the bounds-checked reader. */
#include "test.h"

#include <stdlib.h>

#include <lauxlib.h>
#include <lualib.h>

#include "term.h"

struct round {
    const char *in;     /* ei format string and its arguments are built below */
    const char *out;
};

/* Decodes buf as Lua values (term_push_values) and encodes them back as
 * one event's values; the result as text. */
static const char *through_lua(const char *buf, int len, bool *ok)
{
    static char out[4096];
    lua_State *L = luaL_newstate();
    struct term_reader r;
    ei_x_buff x;
    int n;

    term_reader_init(&r, (const unsigned char *)buf, (size_t)len);
    *ok = term_version(&r);
    n = *ok ? term_push_values(L, &r) : -1;
    *ok = n >= 0 && r.i == (size_t)len;
    if (!*ok) {
        lua_close(L);
        return "<refused>";
    }
    lua_createtable(L, n, 0);
    for (int k = n; k >= 1; k--) {
        lua_insert(L, -2);
        lua_rawseti(L, -2, k);
    }
    ei_x_new_with_version(&x);
    term_encode_values(L, -1, &x);
    snprintf(out, sizeof out, "%s", term_text(x.buff, x.index));
    ei_x_free(&x);
    lua_close(L);
    return out;
}

static const char *round_trip(ei_x_buff *x)
{
    bool ok;
    const char *s = through_lua(x->buff, x->index, &ok);
    ei_x_free(x);
    return s;
}

static void values_cross_both_ways(void)
{
    ei_x_buff x;


    ei_x_new_with_version(&x);
    ei_x_format_wo_ver(&x, "{~i,~i}", 20, 20);
    CHECK_STR(round_trip(&x), "{20,20}");

    ei_x_new_with_version(&x);
    ei_x_format_wo_ver(&x, "~f", 2.5);
    CHECK_STR(round_trip(&x), "2.5");

    ei_x_new_with_version(&x);
    ei_x_format_wo_ver(&x, "~f", 3.0);           /* integral: an integer */
    CHECK_STR(round_trip(&x), "3");

    ei_x_new_with_version(&x);
    ei_x_format_wo_ver(&x, "{}");                /* no values */
    CHECK_STR(round_trip(&x), "{}");

    ei_x_new_with_version(&x);
    ei_x_format_wo_ver(&x, "{true,false,other}");
    CHECK_STR(round_trip(&x), "{true,false,<<\"other\">>}");


    ei_x_new_with_version(&x);
    ei_x_format_wo_ver(&x, "[~i,[~i]]", 1, 2);   /* one value: a list */
    CHECK_STR(round_trip(&x), "[1,[2]]");

    ei_x_new_with_version(&x);
    ei_x_encode_empty_list(&x);                  /* [] */
    CHECK_STR(round_trip(&x), "[]");

    ei_x_new_with_version(&x);
    ei_x_encode_binary(&x, "hi", 2);
    CHECK_STR(round_trip(&x), "<<\"hi\">>");

    ei_x_new_with_version(&x);
    ei_x_encode_map_header(&x, 1);
    ei_x_encode_atom(&x, "k");
    ei_x_encode_long(&x, 1);
    CHECK_STR(round_trip(&x), "#{<<\"k\">>=>1}");

    ei_x_new_with_version(&x);
    ei_x_encode_longlong(&x, -123456789012LL);
    CHECK_STR(round_trip(&x), "-123456789012");
}

static void malformed_terms_are_refused(void)
{
    static const unsigned char cases[][16] = {
        {131},                              /* nothing */
        {131, 104, 2, 97, 1},               /* a tuple one element short */
        {131, 108, 0, 0, 0, 1, 97, 1, 97, 2}, /* an improper list */
        {131, 109, 0, 0, 1, 0, 'x'},        /* a binary longer than the frame */
        {131, 108, 255, 255, 255, 255, 106},  /* a list longer than the frame */
        {131, 103, 100, 0, 1, 'a'},         /* a pid: never a value */
        {131, 110, 9, 0, 1, 1, 1, 1, 1, 1, 1, 1, 1}, /* a big of 9 bytes */
        {130, 97, 1},                       /* a wrong version */
    };
    static const int lens[] = {1, 5, 10, 7, 7, 6, 13, 3};

    for (size_t k = 0; k < sizeof lens / sizeof lens[0]; k++) {
        bool ok;
        struct term_reader r;
        (void)through_lua((const char *)cases[k], lens[k], &ok);
        CHECK(!ok);
        term_reader_init(&r, cases[k], (size_t)lens[k]);
        CHECK(!(term_version(&r) && term_skip(&r) && r.i == (size_t)lens[k]));
    }
}

static void deep_nesting_is_refused(void)
{
    unsigned char buf[1 + 2 * 100 + 1];
    struct term_reader r;
    bool ok;
    size_t n = 0;

    buf[n++] = 131;
    for (int k = 0; k < 100; k++) {
        buf[n++] = 104;                     /* {{{...}}} */
        buf[n++] = 1;
    }
    buf[n++] = 106;
    term_reader_init(&r, buf, n);
    CHECK(term_version(&r));
    CHECK(!term_skip(&r));
    (void)through_lua((const char *)buf, (int)n, &ok);
    CHECK(!ok);
}

/* Lua values that cannot cross raise a Lua error naming what. */
static int encode_global(lua_State *L)
{
    ei_x_buff *x = lua_touserdata(L, 1);
    lua_getglobal(L, "v");
    term_encode(L, -1, x);
    return 0;
}

static const char *encode_lua(const char *code)
{
    static char out[512];
    lua_State *L = luaL_newstate();
    ei_x_buff x;

    luaL_openlibs(L);
    ei_x_new_with_version(&x);
    if (luaL_dostring(L, code) != 0)
        snprintf(out, sizeof out, "load: %s", lua_tostring(L, -1));
    else if (lua_cpcall(L, encode_global, &x) != 0)
        snprintf(out, sizeof out, "error: %s", lua_tostring(L, -1));
    else
        snprintf(out, sizeof out, "%s", term_text(x.buff, x.index));
    ei_x_free(&x);
    lua_close(L);
    return out;
}

static void lua_values_become_terms(void)
{
    CHECK_STR(encode_lua("v = {1, 2.5, 'a', true}"), "[1,2.5,<<\"a\">>,true]");
    CHECK_STR(encode_lua("v = {}"), "[]");
    CHECK_STR(encode_lua("v = {x = 1}"), "#{<<\"x\">>=>1}");
    CHECK_STR(encode_lua("v = {[1] = 1, [3] = 3}"), "#{1=>1,3=>3}");
    CHECK_STR(encode_lua("v = nil"), "nil");
    CHECK_STR(encode_lua("v = 2^53"), "9007199254740992");
    CHECK_STR(encode_lua("v = print"), "error: cannot send a function");
    CHECK_STR(encode_lua("v = 1/0"), "error: cannot send an infinite number");
    CHECK_STR(encode_lua("v = {}; v[1] = v"), "error: value nested too deeply (or cyclic) to send");
}

const struct test_case term_tests[] = {
    TEST_CASE(values_cross_both_ways),
    TEST_CASE(malformed_terms_are_refused),
    TEST_CASE(deep_nesting_is_refused),
    TEST_CASE(lua_values_become_terms),
    {NULL, NULL}};
