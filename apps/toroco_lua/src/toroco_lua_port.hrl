%% The one message toroco_lua_port sends on its own (see its module doc):
%% the lua_port program died, to each process with a Lua state in it.
-define(LUA_PORT_DOWN(Why), {toroco_lua_port, down, Why}).
