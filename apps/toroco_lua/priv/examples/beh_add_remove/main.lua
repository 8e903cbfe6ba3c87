-- /// Torocó verification program: removing and adding a behavior ///
local toroco = require 'toroco.toroco'
local device = require 'toroco.device'
local behavior = require 'toroco.behavior'

toroco.load_behavior(behavior.echo, 'behaviors/release_echo')
toroco.load_behavior(behavior.controller, 'behaviors/add_remove')

toroco.set_inputs(behavior.echo, {left = device.mouse.left, right = device.mouse.right})
toroco.set_inputs(behavior.controller, {left = device.mouse.left, right = device.mouse.right})
toroco.set_inputs(device.actuator, {
  signal = behavior.echo.signal,
  status = behavior.controller.status,
})

toroco.run()
