-- /// Line follower: the grey sensor's readings converted where they are
-- polled, as the original's configure_polling did ///
local toroco = require 'toroco.toroco'
local device = require 'toroco.device'
local behavior = require 'toroco.behavior'

local threshold = 500
toroco.configure_polling(device.trc_grey_left.value, 0.05, function(raw)
  return raw > threshold, raw
end)

toroco.load_behavior(behavior.follower, 'behaviors/follower')
toroco.set_inputs(behavior.follower, {left = device.trc_grey_left.value})
toroco.set_inputs(device.trc_motor, {setvel2mtr = behavior.follower.motors})

toroco.run()
