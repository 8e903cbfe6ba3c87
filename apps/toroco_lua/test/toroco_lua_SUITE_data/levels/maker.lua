-- /// maker: on `make', adds child, whose trigger is written here; child
-- fails on 'boom' ///
local toroco = require 'toroco.toroco'
local device = require 'toroco.device'
local behavior = require 'toroco.behavior'
local input = toroco.input
local made = 0
local lives = 0          -- the child's starts: this state outlives them

return toroco.trigger(input.make, function(event, value)
  made = made + 1
  if made == 1 then
    toroco.add_behavior(behavior.child, function()
      lives = lives + 1
      while true do
        local v = toroco.wait_for_input(input.x)
        if v == 'boom' then error('boom in child') end
        toroco.send_output {out = {v, lives}}
      end
    end)
    toroco.set_inputs(behavior.child, {x = device.s.value})
    toroco.set_inputs(device.a, {child = behavior.child.out})
  end
  toroco.send_output {made = {made}}
end)
