-- /// echo: signals each release, counted from its start ///
local toroco = require 'toroco.toroco'
local input = toroco.input
local n = 0

local function echo(event, value)
  if value == 'released' then
    n = n + 1
    toroco.send_output {signal = {'released', event, n}}
  end
end

return toroco.trigger(input.left, echo), toroco.trigger(input.right, echo)
