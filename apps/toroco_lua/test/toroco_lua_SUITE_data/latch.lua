-- The thesis' trc_avoid: latch the motors while the sensor sees something.
local toroco = require 'toroco.toroco'
local input = toroco.input
local params = toroco.params

return toroco.trigger(input.update, function(event, value)
  if value > 0 then
    print('Avoiding!')
    toroco.set_output {motors_setvel = params.motors_vel}
  else
    toroco.unset_output()
  end
end)
