-- /// controller: a left press removes echo, a right press adds it back ///
local toroco = require 'toroco.toroco'
local device = require 'toroco.device'
local behavior = require 'toroco.behavior'
local input = toroco.input
local present = true

local function on_left(event, value)
  if value == 'pressed' and present then
    toroco.remove_behavior(behavior.echo)
    present = false
    toroco.send_output {status = {'removed'}}
  end
end

local function on_right(event, value)
  if value == 'pressed' and not present then
    toroco.load_behavior(behavior.echo, 'behaviors/release_echo')
    toroco.set_inputs(behavior.echo, {left = device.mouse.left, right = device.mouse.right})
    toroco.set_inputs(device.actuator, {signal = behavior.echo.signal})
    present = true
    toroco.send_output {status = {'added'}}
  end
end

return toroco.trigger(input.left, on_left), toroco.trigger(input.right, on_right)
