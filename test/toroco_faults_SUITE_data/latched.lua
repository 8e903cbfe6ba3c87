-- The fault suite's Lua behavior: latches {'latched', 'lua'} on `out' when it
-- starts, as tb_relay does with a latch, and fails as its `kind' input says.
local toroco = require 'toroco'

toroco.set_output {out = {'latched', 'lua'}}

return toroco.trigger(toroco.input.kind, function(event, kind)
  if kind == 'error' then
    local t = nil
    return t.field
  elseif kind == 'loop' then
    while true do end
  elseif kind == 'memory' then
    local keep = {}
    for i = 1, 1e9 do keep[i] = string.rep('x', 100) .. i end
  end
end)
