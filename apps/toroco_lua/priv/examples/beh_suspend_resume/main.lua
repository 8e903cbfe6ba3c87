-- /// Torocó verification program: suspending and resuming a behavior ///
local toroco = require 'toroco.toroco'
local device = require 'toroco.device'
local behavior = require 'toroco.behavior'

toroco.load_behavior(behavior.counter, 'behaviors/click_counter')
toroco.load_behavior(behavior.display, 'behaviors/display')
toroco.load_behavior(behavior.suspender, 'behaviors/suspender')

toroco.set_inputs(behavior.counter, {left = device.mouse.left, right = device.mouse.right})
toroco.set_inputs(behavior.display, {count = behavior.counter.count})
toroco.set_inputs(behavior.suspender, {left = device.mouse.left, right = device.mouse.right})
toroco.set_inputs(device.actuator, {
  signal = behavior.display.signal,
  status = behavior.suspender.status,
})

toroco.run()
