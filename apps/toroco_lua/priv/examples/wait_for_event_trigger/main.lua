-- /// Torocó verification program: wait for an event in a trigger ///
local toroco = require 'toroco.toroco'
local device = require 'toroco.device'
local behavior = require 'toroco.behavior'

toroco.load_behavior(behavior.trigger, 'behaviors/trigger',
                     {timeout = toroco.params.timeout or 2})
toroco.set_inputs(behavior.trigger, {left = device.mouse.left, right = device.mouse.right})
toroco.set_inputs(device.actuator, {signal = behavior.trigger.signal})

toroco.run()
