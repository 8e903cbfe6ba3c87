-- /// follower: steers toward the line's side ///
local toroco = require 'toroco.toroco'
local input = toroco.input

return toroco.trigger(input.left, function(event, on_line, raw)
  if on_line then
    toroco.send_output {motors = {10, 20, raw}}
  else
    toroco.send_output {motors = {20, 10, raw}}
  end
end)
