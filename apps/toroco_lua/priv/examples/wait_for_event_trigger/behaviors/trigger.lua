-- /// trigger: a left press arms it; silence if the right press comes in
-- time, `timeout' if it does not ///
local toroco = require 'toroco.toroco'
local input = toroco.input
local timeout = toroco.params.timeout

local function armed(event, value)
  if value ~= 'pressed' then return end
  toroco.send_output {signal = {'armed'}}
  local deadline = os.clock() + timeout
  while true do
    local left = deadline - os.clock()
    if left <= 0 then
      toroco.send_output {signal = {'timeout'}}
      return
    end
    local v = toroco.wait_for_input(input.right, left)
    if v == nil then
      toroco.send_output {signal = {'timeout'}}
      return
    elseif v == 'pressed' then
      return
    end
  end
end

return toroco.trigger(input.left, armed)
