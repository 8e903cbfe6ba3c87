-- /// The Torobot, as a program for the original Torocó ///
-- A red follower over a random wanderer, an obstacle avoider and two turn
-- triggers on the mouse buttons, all on the servos (lowest priority first).
local toroco = require 'toroco.toroco'
local device = require 'toroco.device'
local behavior = require 'toroco.behavior'

toroco.load_behavior(behavior.wander, 'behaviors/wander', {speed = 90, turn = 50})
toroco.load_behavior(behavior.avoid, 'behaviors/avoid', {turn = 50, hold = 0.4})
toroco.load_behavior(behavior.turn, 'behaviors/turn', {turn = 50, seconds = 1})
toroco.load_behavior(behavior.red_follower, 'behaviors/red_follower',
                     {straight = 80, soft = {80, 50}, hard = {80, 20}, soft_px = 25, hard_px = 50})

toroco.set_inputs(behavior.avoid, {left = device.ir.left, right = device.ir.right})
toroco.set_inputs(behavior.turn, {
  leftbutton = device.mice.leftbutton,
  rightbutton = device.mice.rightbutton,
})
toroco.set_inputs(behavior.red_follower, {update = device.camera.update})
toroco.set_inputs(device.servo_motors, {
  setvel2mtr = {
    behavior.wander.motors,
    behavior.avoid.motors,
    behavior.turn.motors,
    behavior.red_follower.motors,
  },
})

toroco.run()
