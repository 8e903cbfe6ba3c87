-- The stress test's relay in Lua: each event on `in' goes on as `out'.
local toroco = require 'toroco'

return toroco.trigger(toroco.input['in'], function(event, ...)
  toroco.send_output {out = {...}}
end)
