-- The Torobot's layer 0 in Lua: latches {80, 80} on motors as it starts,
-- so a new Lua state (after its program died) sets it again.
local toroco = require 'toroco'

toroco.set_output {motors = {80, 80}}

return {}
