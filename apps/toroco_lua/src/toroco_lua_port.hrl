%% The one message toroco_lua_port sends on its own (see its module doc):
%% the lua_port program died, to each process with a Lua state in it, with
%% the ids of its states that went with it.
-define(LUA_PORT_DOWN(Ids, Why), {toroco_lua_port, down, Ids, Why}).
