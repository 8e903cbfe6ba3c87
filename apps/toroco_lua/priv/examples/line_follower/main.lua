-- /// The Torobot following a line of dark tape, as a program for the ///
-- /// original Torocó: its two grey sensors polled with a converter   ///
-- Each sensor's raw reading (0..1023) becomes `true' over the line where
-- it is polled, as the original's configure_polling did; the follower
-- steers away from the side that sees the line.
local toroco = require 'toroco.toroco'
local device = require 'toroco.device'
local behavior = require 'toroco.behavior'

local threshold = 500
local function dark(raw)
  return raw > threshold
end
toroco.configure_polling(device.trc_grey_left.value, 0.05, dark)
toroco.configure_polling(device.trc_grey_right.value, 0.05, dark)

toroco.load_behavior(behavior.follower, 'behaviors/follower',
                     {straight = {40, 40}, left = {10, 40}, right = {40, 10}})
toroco.set_inputs(behavior.follower, {
  left = device.trc_grey_left.value,
  right = device.trc_grey_right.value,
})
toroco.set_inputs(device.trc_motor, {setvel2mtr = behavior.follower.motors})

toroco.run()
