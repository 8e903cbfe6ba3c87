-- /// Torocó verification program: inhibition and suppression ///
local toroco = require 'toroco.toroco'
local device = require 'toroco.device'
local behavior = require 'toroco.behavior'

local window = toroco.params.window or 2.5

toroco.load_behavior(behavior.lower, 'behaviors/press_relay')
toroco.load_behavior(behavior.upper, 'behaviors/takeover', {window = window})

toroco.set_inputs(behavior.lower, {left = device.mouse.left, right = device.mouse.right})
toroco.set_inputs(behavior.upper, {left = device.mouse.left, right = device.mouse.right})
toroco.set_inhibitors(behavior.lower, {signal = behavior.upper.inhibit})

-- sources lowest priority first, as the original lists them
toroco.set_inputs(device.actuator, {
  signal = {behavior.lower.signal, behavior.upper.signal},
  monitor = {behavior.lower.signal},
})

toroco.run()
