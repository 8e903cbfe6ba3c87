-- /// sequence: left then right within the timeout ///
local toroco = require 'toroco.toroco'
local input = toroco.input
local timeout = toroco.params.timeout

local function wait_press(i, seconds)
  local deadline = seconds and os.clock() + seconds
  while true do
    local v = toroco.wait_for_input(i, deadline and math.max(deadline - os.clock(), 0))
    if v == nil or v == 'pressed' then return v end
  end
end

return function()
  while true do
    wait_press(input.left)
    toroco.send_output {signal = {'left_seen'}}
    if wait_press(input.right, timeout) then
      toroco.send_output {signal = {'sequence_done'}}
    else
      toroco.send_output {signal = {'timeout'}}
    end
  end
end
