-- /// red_follower: charge the red blob the camera sees ///
local toroco = require 'toroco.toroco'
local input = toroco.input
local params = toroco.params
local last

return toroco.trigger(input.update, function(event, x, y)
  local command
  if x == nil then
    if last then toroco.unset_output() end
    last = nil
    return
  elseif x > params.hard_px then
    command = {params.hard[1], params.hard[2]}
  elseif x > params.soft_px then
    command = {params.soft[1], params.soft[2]}
  elseif x < -params.hard_px then
    command = {params.hard[2], params.hard[1]}
  elseif x < -params.soft_px then
    command = {params.soft[2], params.soft[1]}
  else
    command = {params.straight, params.straight}
  end
  local key = command[1] .. ',' .. command[2]
  if key ~= last then
    toroco.set_output {motors = command}
    last = key
  end
end)
