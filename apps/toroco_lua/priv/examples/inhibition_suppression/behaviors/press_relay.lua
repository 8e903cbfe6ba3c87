-- /// lower: signals each press ///
local toroco = require 'toroco.toroco'
local input = toroco.input

local function relay(event, value)
  if value == 'pressed' then
    toroco.send_output {signal = {'lower', event}}
  end
end

return toroco.trigger(input.left, relay), toroco.trigger(input.right, relay)
