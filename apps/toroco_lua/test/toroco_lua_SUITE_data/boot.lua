-- Says it started, then echoes.
local toroco = require 'toroco'
toroco.send_output {booted = {}}
return toroco.trigger(toroco.input.value, function(event, v)
  toroco.send_output {echo = {v}}
end)
