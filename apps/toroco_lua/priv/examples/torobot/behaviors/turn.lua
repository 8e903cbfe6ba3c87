-- /// turn: a mouse button turns the robot that way for a while ///
local toroco = require 'toroco.toroco'
local input = toroco.input
local params = toroco.params

local function turn(left)
  return function(event, pressed)
    if pressed then
      local t = params.turn
      if left then
        toroco.send_output {motors = {-t, t, timeout = params.seconds}}
      else
        toroco.send_output {motors = {t, -t, timeout = params.seconds}}
      end
    end
  end
end

return toroco.trigger(input.leftbutton, turn(true)),
       toroco.trigger(input.rightbutton, turn(false))
