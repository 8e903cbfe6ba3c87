-- /// Torocó verification program: sensor signalling ///
local toroco = require 'toroco.toroco'
local device = require 'toroco.device'
local behavior = require 'toroco.behavior'

toroco.load_behavior(behavior.signaller, 'behaviors/signaller')

toroco.set_inputs(behavior.signaller, {
  left = device.mouse.left,
  right = device.mouse.right,
})
toroco.set_inputs(device.actuator, {
  signal = behavior.signaller.signal,
})

toroco.run()
