-- Draws from math.random, seeded as the original's programs seed it.
local toroco = require 'toroco'
local input = toroco.input
math.randomseed(toroco.params.seed or os.time())

return toroco.trigger(input.go, function(event)
  toroco.send_output {drawn = {math.random(1000), os.time()}}
end)
