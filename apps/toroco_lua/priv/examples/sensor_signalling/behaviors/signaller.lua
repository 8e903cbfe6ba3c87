-- /// signaller: passes each button event on ///
local toroco = require 'toroco.toroco'
local input = toroco.input

local function signal(event, value)
  toroco.send_output {signal = {event, value}}
end

return toroco.trigger(input.left, signal), toroco.trigger(input.right, signal)
