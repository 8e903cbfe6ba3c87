local toroco = require 'toroco'
local lib = require 'lib.limits'

local function fault(event, kind)
  if kind == 'error' then
    local t = nil
    return t.field
  elseif kind == 'loop' then
    lib.spin()
  elseif kind == 'memory' then
    lib.hoard()
  elseif kind == 'pattern' then
    lib.backtrack()
  end
  toroco.send_output {alive = {kind}}
end

return toroco.trigger(toroco.input.kind, fault)
