-- Takes its time over each input (a long computation), then answers.
local toroco = require 'toroco'

return toroco.trigger(toroco.input.value, function(event, v)
  local x = 0
  for i = 1, 3000000 do x = x + i % 7 end
  toroco.send_output {done = {v}}
end)
