-- /// Open ports: wiring names inputs the behavior never reads ///
local toroco = require 'toroco.toroco'
local device = require 'toroco.device'
local behavior = require 'toroco.behavior'

toroco.load_behavior(behavior.counter, 'behaviors/counter')

-- `reset' and `spare' are never read by counter.lua; the original took them
toroco.set_inputs(behavior.counter, {
  tick = device.mouse.left,
  reset = device.mouse.right,
  spare = device.mouse.left,
})
toroco.set_inputs(device.actuator, {signal = behavior.counter.count})

toroco.run()
