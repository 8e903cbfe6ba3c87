-- /// Torocó verification program: wait for events in a coroutine ///
local toroco = require 'toroco.toroco'
local device = require 'toroco.device'
local behavior = require 'toroco.behavior'

toroco.load_behavior(behavior.sequence, 'behaviors/sequence',
                     {timeout = toroco.params.timeout or 2})
toroco.set_inputs(behavior.sequence, {left = device.mouse.left, right = device.mouse.right})
toroco.set_inputs(device.actuator, {signal = behavior.sequence.signal})

toroco.run()
