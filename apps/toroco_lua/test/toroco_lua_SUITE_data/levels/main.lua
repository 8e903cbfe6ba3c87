-- /// Levels: a behavior hands over to one it makes with inline code ///
local toroco = require 'toroco.toroco'
local device = require 'toroco.device'
local behavior = require 'toroco.behavior'

toroco.load_behavior(behavior.level2, 'behaviors/level2')
toroco.load_behavior(behavior.reporter, 'behaviors/reporter')

toroco.set_inputs(behavior.level2, {left = device.mouse.left})
toroco.set_inputs(behavior.reporter, {level = behavior.level2.level})
toroco.set_inputs(device.actuator, {signal = behavior.reporter.signal})

toroco.run()
