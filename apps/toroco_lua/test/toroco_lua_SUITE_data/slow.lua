-- Takes its time over each input (a long computation: a tenth of a second
-- or more on a fast machine), then answers.
local toroco = require 'toroco'

return toroco.trigger(toroco.input.value, function(event, v)
  local x = 0
  for i = 1, 15000000 do x = x + i % 7 end
  toroco.send_output {done = {v}}
end)
