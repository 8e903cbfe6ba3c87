-- /// upper: a left click suppresses lower's signal for a window, a right
-- click inhibits it for a window ///
local toroco = require 'toroco.toroco'
local input = toroco.input
local window = toroco.params.window

local function on_left(event, value)
  if value == 'released' then
    toroco.send_output {signal = {'upper', 'suppress', timeout = window}}
  end
end

local function on_right(event, value)
  if value == 'released' then
    toroco.send_output {inhibit = {'on', timeout = window}}
    toroco.send_output {signal = {'upper', 'inhibit'}}
  end
end

return toroco.trigger(input.left, on_left), toroco.trigger(input.right, on_right)
