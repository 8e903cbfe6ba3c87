-- /// counter: latches the number of clicks ///
local toroco = require 'toroco.toroco'
local input = toroco.input
local n = 0

local function count(event, value)
  if value == 'released' then
    n = n + 1
    toroco.set_output {count = {n}}
  end
end

return toroco.trigger(input.left, count), toroco.trigger(input.right, count)
