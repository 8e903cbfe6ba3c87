-- /// reporter: passes on the level it is told ///
local toroco = require 'toroco.toroco'
local input = toroco.input

return toroco.trigger(input.level, function(event, ...)
  toroco.send_output {signal = {...}}
end)
