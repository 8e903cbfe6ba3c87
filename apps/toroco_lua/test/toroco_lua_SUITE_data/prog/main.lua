-- A program as the original ran it, from its own folder.
local toroco = require 'toroco.toroco'
local device = require 'toroco.device'
local behavior = require 'toroco.behavior'

toroco.load_behavior(behavior.user, 'behaviors/user')
toroco.set_inputs(behavior.user, {value = device.s.value})
toroco.set_inputs(device.a, {twice = behavior.user.twice})
toroco.run()
