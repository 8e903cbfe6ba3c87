/* Runs every C test case; the last line is "N passed, N failed". */
#include "test.h"

#include <stdlib.h>

bool test_case_failed;

/* Prints one term Erlang-style (binaries as <<"text">>, floats with %g)
 * into out; false if it cannot. Only for the tests' trusted buffers. */
static bool print_term(const char *buf, int *i, char *out, size_t cap, size_t *o);

static void put(char *out, size_t cap, size_t *o, const char *s)
{
    size_t n = strlen(s);
    if (*o + n >= cap)
        n = cap - *o - 1;
    memcpy(out + *o, s, n);
    *o += n;
    out[*o] = '\0';
}

static bool print_list(const char *buf, int *i, char *out, size_t cap, size_t *o)
{
    int n, type, size;
    bool first = true;

    put(out, cap, o, "[");
    for (;;) {
        if (ei_get_type(buf, i, &type, &size) != 0)
            return false;
        if (type == ERL_NIL_EXT) {
            (void)ei_decode_list_header(buf, i, &n);
            break;
        }
        if (type != ERL_LIST_EXT || ei_decode_list_header(buf, i, &n) != 0)
            return false;
        for (int k = 0; k < n; k++) {
            if (!first)
                put(out, cap, o, ",");
            first = false;
            if (!print_term(buf, i, out, cap, o))
                return false;
        }
    }
    put(out, cap, o, "]");
    return true;
}

static bool print_term(const char *buf, int *i, char *out, size_t cap, size_t *o)
{
    int type, size, n;
    char tmp[64];

    if (ei_get_type(buf, i, &type, &size) != 0)
        return false;
    switch (type) {
    case ERL_ATOM_EXT: case ERL_SMALL_ATOM_EXT: case ERL_ATOM_UTF8_EXT: case ERL_SMALL_ATOM_UTF8_EXT: {
        char a[MAXATOMLEN_UTF8];
        if (ei_decode_atom(buf, i, a) != 0)
            return false;
        put(out, cap, o, a);
        return true;
    }
    case ERL_SMALL_INTEGER_EXT: case ERL_INTEGER_EXT: case ERL_SMALL_BIG_EXT: {
        long long v;
        if (ei_decode_longlong(buf, i, &v) != 0)
            return false;
        snprintf(tmp, sizeof tmp, "%lld", v);
        put(out, cap, o, tmp);
        return true;
    }
    case NEW_FLOAT_EXT: case ERL_FLOAT_EXT: {
        double d;
        if (ei_decode_double(buf, i, &d) != 0)
            return false;
        snprintf(tmp, sizeof tmp, "%g", d);
        put(out, cap, o, tmp);
        return true;
    }
    case ERL_BINARY_EXT: {
        char *b = malloc((size_t)size + 1);
        long len;
        if (b == NULL || ei_decode_binary(buf, i, b, &len) != 0) {
            free(b);
            return false;
        }
        b[len] = '\0';
        put(out, cap, o, "<<\"");
        put(out, cap, o, b);
        put(out, cap, o, "\">>");
        free(b);
        return true;
    }
    case ERL_SMALL_TUPLE_EXT: case ERL_LARGE_TUPLE_EXT:
        if (ei_decode_tuple_header(buf, i, &n) != 0)
            return false;
        put(out, cap, o, "{");
        for (int k = 0; k < n; k++) {
            if (k > 0)
                put(out, cap, o, ",");
            if (!print_term(buf, i, out, cap, o))
                return false;
        }
        put(out, cap, o, "}");
        return true;
    case ERL_NIL_EXT: case ERL_LIST_EXT:
        return print_list(buf, i, out, cap, o);
    case ERL_MAP_EXT:
        if (ei_decode_map_header(buf, i, &n) != 0)
            return false;
        put(out, cap, o, "#{");
        for (int k = 0; k < n; k++) {
            if (k > 0)
                put(out, cap, o, ",");
            if (!print_term(buf, i, out, cap, o))
                return false;
            put(out, cap, o, "=>");
            if (!print_term(buf, i, out, cap, o))
                return false;
        }
        put(out, cap, o, "}");
        return true;
    default:
        return false;
    }
}

const char *term_text(const char *buf, int len)
{
    static char out[8192];
    int index = 0, version;
    size_t o = 0;

    out[0] = '\0';
    if (ei_decode_version(buf, &index, &version) != 0 ||
        !print_term(buf, &index, out, sizeof out, &o) || index != len)
        return "<bad term>";
    return out;
}

int main(void)
{
    const struct test_case *suites[] = {frame_tests, term_tests, port_tests};

    ei_init();
    return run_suites(suites, sizeof suites / sizeof suites[0], NULL);
}
