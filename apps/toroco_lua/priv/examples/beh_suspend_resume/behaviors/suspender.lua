-- /// suspender: a left press suspends display, a right press resumes it ///
local toroco = require 'toroco.toroco'
local behavior = require 'toroco.behavior'
local input = toroco.input
local suspended = false

local function on_left(event, value)
  if value == 'pressed' and not suspended then
    toroco.suspend_behavior(behavior.display)
    suspended = true
    toroco.send_output {status = {'suspended'}}
  end
end

local function on_right(event, value)
  if value == 'pressed' and suspended then
    toroco.resume_behavior(behavior.display)
    suspended = false
    toroco.send_output {status = {'resumed'}}
  end
end

return toroco.trigger(input.left, on_left), toroco.trigger(input.right, on_right)
