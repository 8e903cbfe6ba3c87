local toroco = require 'toroco'
local device = require 'toroco.device'
local behavior = require 'toroco.behavior'

toroco.load_behavior(behavior.e, '../echo')
toroco.set_inputs(behavior.e, {value = device.nowhere.value})
toroco.run()
