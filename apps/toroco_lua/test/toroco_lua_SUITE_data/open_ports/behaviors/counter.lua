-- /// counter: counts ticks ///
-- A comment naming input.ghost or send_output{ghost = 1} makes no port,
-- and neither does the string below.
local toroco = require 'toroco.toroco'
local input = toroco.input
local n = 0
local note = "toroco.send_output {phantom = {1}} and input.phantom"

return toroco.trigger(input.tick, function(event, value)
  n = n + 1
  toroco.send_output {count = {n}}
  toroco.send_output {['made_' .. 'later'] = {n}}
end)
