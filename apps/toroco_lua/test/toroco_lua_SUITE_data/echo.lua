-- Sends back what it gets on `value', as it got it, and a few values of its own.
local toroco = require 'toroco'
local input = toroco.input

return toroco.trigger(input.value, function(event, ...)
  toroco.send_output {echo = {...}}
  toroco.send_output {count = {select('#', ...)}}
  toroco.send_output {made = {1, 2.5, 'text', true, {1, 2}, {k = 'v'}}}
end)
