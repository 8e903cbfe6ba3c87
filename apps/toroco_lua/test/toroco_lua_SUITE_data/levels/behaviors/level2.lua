-- /// level2: reports 2; on a release, removes itself and puts level3
-- in its place, a behavior whose trigger is written right here ///
local toroco = require 'toroco.toroco'
local device = require 'toroco.device'
local behavior = require 'toroco.behavior'
local input = toroco.input

return toroco.trigger(input.left, function(event, value)
  if value == 'pressed' then
    toroco.send_output {level = {2}}
  else
    toroco.remove_behavior(behavior.level2)
    toroco.add_behavior(behavior.level3, {
      toroco.trigger(input.left, function(event, v)
        toroco.send_output {level = {toroco.params.level, v}}
      end),
    }, {level = 3})
    toroco.set_inputs(behavior.level3, {left = device.mouse.left})
    toroco.set_inputs(behavior.reporter, {level = behavior.level3.level})
  end
end)
