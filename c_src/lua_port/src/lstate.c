/* See lstate.h and prelude.lua. */
#include "lstate.h"

#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include <lauxlib.h>
#include <lualib.h>

#include "prelude.h"

#define HOOK_EVERY 1000          /* instructions between two budget checks */
#define MODULE_MAX (1u << 20)    /* bytes of one Lua source file */

/* ---- limits ------------------------------------------------------------ */

static void *cap_alloc(void *ud, void *ptr, size_t osize, size_t nsize)
{
    struct lstate *s = ud;

    if (nsize == 0) {
        free(ptr);
        s->mem -= osize;
        return NULL;
    }
    if (nsize > osize && s->mem + (nsize - osize) > s->mem_cap) {
        if (s->ready)
            s->limit = LIMIT_MEMORY;
        return NULL;
    }
    void *p = realloc(ptr, nsize);
    if (p == NULL)
        return NULL;
    s->mem = s->mem - osize + nsize;
    return p;
}

static struct lstate *of(lua_State *L)
{
    void *ud;
    (void)lua_getallocf(L, &ud);
    return ud;
}

static void note_place(struct lstate *s, lua_State *L, lua_Debug *ar)
{
    if (lua_getinfo(L, "Sl", ar) && ar->source[0] == '@') {
        snprintf(s->fail_file, sizeof s->fail_file, "%s", ar->source + 1);
        s->fail_line = ar->currentline;
    }
}

static void budget_hook(lua_State *L, lua_Debug *ar)
{
    struct lstate *s = of(L);

    s->used += HOOK_EVERY;
    if (s->used <= s->budget && s->limit != LIMIT_BUDGET)
        return;
    if (s->limit == LIMIT_NONE) {
        s->limit = LIMIT_BUDGET;
        note_place(s, L, ar);
    }
    /* from now on every instruction of this thread fails, so a pcall in a
     * loop cannot keep it going */
    lua_sethook(L, budget_hook, LUA_MASKCOUNT, 1);
    luaL_error(L, "instruction budget exhausted");
}

/* ---- actions ----------------------------------------------------------- */

static ei_x_buff *action(struct lstate *s, int arity)
{
    ei_x_encode_list_header(&s->actions, 1);
    ei_x_encode_tuple_header(&s->actions, arity);
    s->n_actions++;
    return &s->actions;
}

/* C.emit(kind, out, values, hold): hold nil (the wiring's), ms or 'infinity' */
static int l_emit(lua_State *L)
{
    struct lstate *s = of(L);
    const char *kind = luaL_checkstring(L, 1);
    size_t n;
    const char *out = luaL_checklstring(L, 2, &n);
    bool send = strcmp(kind, "send") == 0;
    ei_x_buff *x;

    /* the value first, into the scratch buffer: a value that cannot cross
     * raises here and leaves no half-written action behind */
    s->scratch.index = 0;
    term_encode_values(L, 3, &s->scratch);
    x = action(s, send ? 4 : 3);
    ei_x_encode_atom(x, send ? "send" : "set");
    ei_x_encode_binary(x, out, (long)n);
    ei_x_append_buf(x, s->scratch.buff, s->scratch.index);
    if (send) {
        if (lua_type(L, 4) == LUA_TNUMBER)
            ei_x_encode_longlong(x, (long long)lua_tonumber(L, 4));
        else if (lua_type(L, 4) == LUA_TSTRING)
            ei_x_encode_atom(x, "infinity");
        else
            ei_x_encode_atom(x, "default");
    }
    return 0;
}

/* C.unset([out]) */
static int l_unset(lua_State *L)
{
    struct lstate *s = of(L);
    size_t n;
    ei_x_buff *x = action(s, 2);

    ei_x_encode_atom(x, "unset");
    if (lua_isnoneornil(L, 1)) {
        ei_x_encode_atom(x, "all");
    } else {
        const char *out = luaL_checklstring(L, 1, &n);
        ei_x_encode_binary(x, out, (long)n);
    }
    return 0;
}

/* C.main(op, line, args): a wiring call, {main, Op, Line, Args} */
static int l_main(lua_State *L)
{
    struct lstate *s = of(L);
    size_t n;
    const char *op = luaL_checklstring(L, 1, &n);
    long line = (long)luaL_checknumber(L, 2);
    ei_x_buff *x;

    s->scratch.index = 0;
    term_encode(L, 3, &s->scratch);
    x = action(s, 4);
    ei_x_encode_atom(x, "main");
    ei_x_encode_binary(x, op, (long)n);
    ei_x_encode_long(x, line);
    ei_x_append_buf(x, s->scratch.buff, s->scratch.index);
    return 0;
}

static int text_action(lua_State *L, const char *what)
{
    struct lstate *s = of(L);
    size_t n;
    const char *text = luaL_checklstring(L, 1, &n);
    ei_x_buff *x = action(s, 2);

    ei_x_encode_atom(x, what);
    ei_x_encode_binary(x, text, (long)n);
    return 0;
}

static int l_print(lua_State *L)
{
    return text_action(L, "print");
}

/* C.warn(text): {warning, Text}, something the owner should hear of */
static int l_warn(lua_State *L)
{
    return text_action(L, "warning");
}

/* C.timer(task, seq, ms) */
static int l_timer(lua_State *L)
{
    struct lstate *s = of(L);
    ei_x_buff *x = action(s, 4);

    ei_x_encode_atom(x, "timer");
    ei_x_encode_longlong(x, (long long)luaL_checknumber(L, 1));
    ei_x_encode_longlong(x, (long long)luaL_checknumber(L, 2));
    ei_x_encode_longlong(x, (long long)luaL_checknumber(L, 3));
    return 0;
}

/* C.cancel(task) */
static int l_cancel(lua_State *L)
{
    struct lstate *s = of(L);
    ei_x_buff *x = action(s, 2);

    ei_x_encode_atom(x, "cancel");
    ei_x_encode_longlong(x, (long long)luaL_checknumber(L, 1));
    return 0;
}

static int l_now(lua_State *L)
{
    lua_pushnumber(L, (lua_Number)of(L)->now_ms);
    return 1;
}

/* C.fail(file, line, message): a task failed; the dispatch stops after. */
static int l_fail(lua_State *L)
{
    struct lstate *s = of(L);

    if (!s->failed) {
        s->failed = true;
        if (s->limit == LIMIT_NONE || s->fail_file[0] == '\0') {
            snprintf(s->fail_file, sizeof s->fail_file, "%s", luaL_checkstring(L, 1));
            s->fail_line = (long)luaL_checknumber(L, 2);
        }
        snprintf(s->fail_msg, sizeof s->fail_msg, "%s", luaL_checkstring(L, 3));
    }
    return 0;
}

/* Reads dir/rel (at most MODULE_MAX bytes) and loads it as chunk "@rel". */
static int load_source(lua_State *L, const char *dir, const char *rel)
{
    char path[PATH_MAX + 16], chunk[PATH_MAX + 2];
    FILE *f;
    char *buf;
    size_t n;
    int rc;

    snprintf(path, sizeof path, "%s/%s", dir, rel);
    snprintf(chunk, sizeof chunk, "@%s", rel);
    f = fopen(path, "rb");
    if (f == NULL) {
        lua_pushfstring(L, "%s: cannot open", rel);
        return LUA_ERRFILE;
    }
    buf = malloc(MODULE_MAX + 1);
    if (buf == NULL) {
        fclose(f);
        lua_pushstring(L, "out of memory");
        return LUA_ERRMEM;
    }
    n = fread(buf, 1, MODULE_MAX + 1, f);
    fclose(f);
    if (n > MODULE_MAX) {
        free(buf);
        lua_pushfstring(L, "%s: larger than %d bytes", rel, (int)MODULE_MAX);
        return LUA_ERRFILE;
    }
    if (n > 0 && buf[0] == LUA_SIGNATURE[0]) {
        free(buf);
        lua_pushfstring(L, "%s: binary chunks are refused", rel);
        return LUA_ERRSYNTAX;
    }
    rc = luaL_loadbuffer(L, buf, n, chunk);
    free(buf);
    return rc;
}

/* C.loadmodule(name): a module of the program's folder, as a function.
 * Names are dotted words; no way out of the folder. */
static int l_loadmodule(lua_State *L)
{
    struct lstate *s = of(L);
    size_t n;
    const char *name = luaL_checklstring(L, 1, &n);
    char rel[PATH_MAX];

    if (n == 0 || n > 200 || name[0] == '.' || name[n - 1] == '.' || strstr(name, "..") != NULL)
        return luaL_error(L, "module '%s' not found", name);
    for (size_t k = 0; k < n; k++) {
        char c = name[k];
        if (!((c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
              c == '_' || c == '.' || c == '-'))
            return luaL_error(L, "module '%s' not found", name);
        rel[k] = c == '.' ? '/' : c;
    }
    memcpy(rel + n, ".lua", 5);
    if (load_source(L, s->dir, rel) != 0) {
        if (strstr(lua_tostring(L, -1), "cannot open") != NULL)
            return luaL_error(L, "module '%s' not found in the program's folder", name);
        return lua_error(L);
    }
    return 1;
}

static const luaL_Reg port_functions[] = {
    {"emit", l_emit}, {"unset", l_unset}, {"print", l_print}, {"timer", l_timer},
    {"cancel", l_cancel}, {"now", l_now}, {"fail", l_fail}, {"loadmodule", l_loadmodule},
    {"main", l_main}, {"warn", l_warn},
    {NULL, NULL}};

/* ---- activations ------------------------------------------------------- */

enum activation_kind { ACT_BOOT, ACT_INPUT, ACT_TIMER, ACT_ATTACH, ACT_DETACH };

struct activation {
    struct lstate *s;
    enum activation_kind kind;
    struct term_reader *terms;   /* params (boot) or the event's value (input) */
    const char *input;
    long long task, seq;
    int slot;
    bool bad_term;
    bool ok;                     /* attach: the slot exists */
};

static void push_entry(lua_State *L, struct lstate *s, const char *name)
{
    lua_rawgeti(L, LUA_REGISTRYINDEX, s->entry_ref);
    lua_getfield(L, -1, name);
    lua_remove(L, -2);
}

/* The prelude, then the file's chunk through entry.boot. */
static int boot(lua_State *L)
{
    struct activation *a = lua_touserdata(L, 1);
    struct lstate *s = a->s;

    /* only the libraries the sandbox keeps (and debug, which the prelude
     * takes getinfo from and then removes): io and package never exist */
    static const luaL_Reg libs[] = {
        {"", luaopen_base}, {LUA_TABLIBNAME, luaopen_table}, {LUA_STRLIBNAME, luaopen_string},
        {LUA_MATHLIBNAME, luaopen_math}, {LUA_OSLIBNAME, luaopen_os},
        {LUA_DBLIBNAME, luaopen_debug}, {NULL, NULL}};
    for (const luaL_Reg *lib = libs; lib->func != NULL; lib++) {
        lua_pushcfunction(L, lib->func);
        lua_pushstring(L, lib->name);
        lua_call(L, 1, 0);
    }
    if (luaL_loadbuffer(L, prelude_lua, prelude_lua_len, "=toroco") != 0)
        return lua_error(L);
    lua_newtable(L);
    luaL_register(L, NULL, port_functions);
    lua_pushstring(L, s->file);
    if (a->terms != NULL) {
        if (!term_push(L, a->terms)) {
            a->bad_term = true;
            return 0;
        }
    } else {
        lua_newtable(L);
    }
    lua_call(L, 3, 1);
    s->entry_ref = luaL_ref(L, LUA_REGISTRYINDEX);
    s->ready = true;
    push_entry(L, s, "boot");
    if (load_source(L, s->dir, s->file) != 0)
        return lua_error(L);
    lua_call(L, 1, 0);
    /* what the sandbox took away and the file's loading left: an idle
     * state starts small */
    lua_gc(L, LUA_GCCOLLECT, 0);
    return 0;
}

static int dispatch(lua_State *L)
{
    struct activation *a = lua_touserdata(L, 1);
    struct lstate *s = a->s;
    int n;

    switch (a->kind) {
    case ACT_INPUT:
        push_entry(L, s, "input");
        lua_pushnumber(L, a->slot);
        lua_pushstring(L, a->input);
        n = term_push_values(L, a->terms);
        if (n < 0) {
            a->bad_term = true;
            return 0;
        }
        lua_call(L, n + 2, 0);
        return 0;
    case ACT_ATTACH:
    case ACT_DETACH:
        push_entry(L, s, a->kind == ACT_ATTACH ? "attach" : "detach");
        lua_pushnumber(L, a->slot);
        lua_call(L, 1, 1);
        a->ok = lua_toboolean(L, -1);
        return 0;
    case ACT_TIMER:
        push_entry(L, s, "timer");
        lua_pushnumber(L, (lua_Number)a->task);
        lua_pushnumber(L, (lua_Number)a->seq);
        lua_call(L, 2, 0);
        return 0;
    case ACT_BOOT:
        return boot(L);
    }
    return 0;
}

/* An error that escaped every task (a load error, the prelude itself, or
 * memory): file and line from a "chunk:line: message" text when it has one. */
static void escaped(struct lstate *s, const char *msg)
{
    const char *p = msg;

    s->failed = true;
    snprintf(s->fail_file, sizeof s->fail_file, "%s", s->file);
    s->fail_line = 0;
    snprintf(s->fail_msg, sizeof s->fail_msg, "%s", msg);
    while ((p = strchr(p, ':')) != NULL) {
        char *end;
        long line = strtol(p + 1, &end, 10);
        if (end != p + 1 && end[0] == ':' && end[1] == ' ') {
            size_t flen = (size_t)(p - msg);
            if (flen < sizeof s->fail_file) {
                memcpy(s->fail_file, msg, flen);
                s->fail_file[flen] = '\0';
            }
            s->fail_line = line;
            snprintf(s->fail_msg, sizeof s->fail_msg, "%s", end + 2);
            return;
        }
        p++;
    }
}

static void activate(struct activation *a, long long now_ms)
{
    struct lstate *s = a->s;
    int rc;

    if (s->failed)
        return;
    s->now_ms = now_ms;
    s->used = 0;
    rc = lua_cpcall(s->L, dispatch, a);
    if (rc == LUA_ERRMEM && s->limit == LIMIT_NONE) {
        s->limit = LIMIT_MEMORY;
        snprintf(s->fail_file, sizeof s->fail_file, "%s", s->file);
    }
    if (rc != 0) {
        /* the STOP of a failed task (already recorded), or an escape */
        if (!s->failed) {
            const char *msg = lua_tostring(s->L, -1);
            escaped(s, msg != NULL ? msg : "error object is not a string");
        }
        lua_pop(s->L, 1);
    }
    if (s->limit != LIMIT_NONE)
        s->failed = true;
}

/* Slot `slot' held; false only when out of host memory. */
static bool hold(struct lstate *s, int slot)
{
    if (slot < 0)
        return false;
    if (slot >= s->held_cap) {
        int cap = slot + 16;
        unsigned char *grown = realloc(s->held, (size_t)cap);
        if (grown == NULL)
            return false;
        memset(grown + s->held_cap, 0, (size_t)(cap - s->held_cap));
        s->held = grown;
        s->held_cap = cap;
    }
    if (!s->held[slot]) {
        s->held[slot] = 1;
        s->refs++;
    }
    return true;
}

struct lstate *lstate_open(long long id, const struct lstate_opts *opts,
                           struct term_reader *params, long long now_ms)
{
    struct lstate *s = calloc(1, sizeof *s);
    struct activation a = {.kind = ACT_BOOT, .terms = params};

    if (s == NULL)
        return NULL;
    s->id = id;
    s->mem_cap = opts->mem_cap;
    s->budget = opts->budget;
    s->entry_ref = LUA_NOREF;
    snprintf(s->file, sizeof s->file, "%s", opts->file);
    snprintf(s->dir, sizeof s->dir, "%s", opts->dir);
    if (ei_x_new(&s->actions) != 0 || ei_x_new(&s->scratch) != 0 || !hold(s, 0)) {
        free(s->held);
        free(s);
        return NULL;
    }
    s->L = lua_newstate(cap_alloc, s);
    if (s->L == NULL) {
        /* the cap is below what an empty state needs */
        s->limit = LIMIT_MEMORY;
        s->failed = true;
        snprintf(s->fail_file, sizeof s->fail_file, "%s", s->file);
        return s;
    }
    lua_sethook(s->L, budget_hook, LUA_MASKCOUNT, HOOK_EVERY);
    a.s = s;
    activate(&a, now_ms);
    if (a.bad_term && !s->failed) {
        s->failed = true;
        escaped(s, "bad params term");
    }
    return s;
}

bool lstate_input(struct lstate *s, const char *input, struct term_reader *value,
                  long long now_ms)
{
    return lstate_input_slot(s, 0, input, value, now_ms);
}

bool lstate_input_slot(struct lstate *s, int slot, const char *input, struct term_reader *value,
                       long long now_ms)
{
    struct activation a = {.s = s, .kind = ACT_INPUT, .terms = value, .input = input,
                           .slot = slot};
    activate(&a, now_ms);
    return !a.bad_term;
}

bool lstate_attach(struct lstate *s, int slot, long long now_ms)
{
    struct activation a = {.s = s, .kind = ACT_ATTACH, .slot = slot};

    if (slot <= 0)
        return false;
    activate(&a, now_ms);
    if (!a.ok && !s->failed)
        return false;
    if (!hold(s, slot)) {
        s->limit = LIMIT_MEMORY;
        s->failed = true;
    }
    return true;
}

int lstate_detach(struct lstate *s, int slot, bool release)
{
    struct activation a = {.s = s, .kind = ACT_DETACH, .slot = slot};

    if (!s->failed && !s->dead && s->L != NULL) {
        activate(&a, s->now_ms);
        s->actions.index = 0;        /* a closing behavior's actions go nowhere */
        s->n_actions = 0;
        if (s->failed && !lstate_recover(s))
            s->dead = true;
    }
    if (release && slot >= 0 && slot < s->held_cap && s->held[slot]) {
        s->held[slot] = 0;
        s->refs--;
    }
    return s->refs;
}

bool lstate_recover(struct lstate *s)
{
    if (s->L == NULL || !s->ready || s->limit == LIMIT_MEMORY)
        return false;
    s->failed = false;
    s->limit = LIMIT_NONE;
    s->fail_file[0] = '\0';
    s->fail_line = 0;
    s->fail_msg[0] = '\0';
    lua_settop(s->L, 0);
    lua_sethook(s->L, budget_hook, LUA_MASKCOUNT, HOOK_EVERY);
    return true;
}

void lstate_timer(struct lstate *s, long long task, long long seq, long long now_ms)
{
    struct activation a = {.s = s, .kind = ACT_TIMER, .task = task, .seq = seq};
    activate(&a, now_ms);
}

struct waits_of {
    struct lstate *s;
    int slot;                    /* -1: every slot's */
};

static int waits(lua_State *L)
{
    struct waits_of *w = lua_touserdata(L, 1);
    struct lstate *s = w->s;

    push_entry(L, s, "waits");
    if (w->slot >= 0)
        lua_pushnumber(L, w->slot);
    else
        lua_pushnil(L);
    lua_call(L, 1, 1);
    s->scratch.index = 0;
    term_encode(L, -1, &s->scratch);
    return 0;
}

void lstate_waits(struct lstate *s, ei_x_buff *x)
{
    lstate_waits_slot(s, -1, x);
}

void lstate_waits_slot(struct lstate *s, int slot, ei_x_buff *x)
{
    struct waits_of w = {.s = s, .slot = slot};

    if (s->failed || s->dead || s->L == NULL || lua_cpcall(s->L, waits, &w) != 0) {
        if (s->L != NULL && lua_gettop(s->L) > 0)
            lua_settop(s->L, 0);
        ei_x_encode_empty_list(x);
        return;
    }
    ei_x_append_buf(x, s->scratch.buff, s->scratch.index);
}

void lstate_take_actions(struct lstate *s, ei_x_buff *x)
{
    ei_x_append_buf(x, s->actions.buff, s->actions.index);
    ei_x_encode_empty_list(x);
    s->actions.index = 0;
    s->n_actions = 0;
}

void lstate_encode_failure(const struct lstate *s, ei_x_buff *x)
{
    if (s->limit != LIMIT_NONE) {
        ei_x_encode_tuple_header(x, 3);
        ei_x_encode_atom(x, "lua_limit");
        ei_x_encode_binary(x, s->fail_file, (long)strlen(s->fail_file));
        ei_x_encode_atom(x, s->limit == LIMIT_BUDGET ? "budget" : "memory");
        return;
    }
    ei_x_encode_tuple_header(x, 4);
    ei_x_encode_atom(x, "lua_error");
    ei_x_encode_binary(x, s->fail_file, (long)strlen(s->fail_file));
    ei_x_encode_longlong(x, s->fail_line);
    ei_x_encode_binary(x, s->fail_msg, (long)strlen(s->fail_msg));
}

void lstate_close(struct lstate *s)
{
    if (s == NULL)
        return;
    if (s->L != NULL) {
        s->mem_cap = (size_t)-1;     /* closing only frees, but never refuse */
        lua_close(s->L);
    }
    ei_x_free(&s->actions);
    ei_x_free(&s->scratch);
    free(s->held);
    free(s);
}
