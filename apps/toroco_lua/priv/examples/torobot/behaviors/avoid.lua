-- /// avoid: spin away from what an IR sensor sees near ///
local toroco = require 'toroco.toroco'
local input = toroco.input
local params = toroco.params

local function away(event, near)
  if near == 1 then
    local t = params.turn
    if event == 'left' then
      toroco.send_output {motors = {t, -t, timeout = params.hold}}
    else
      toroco.send_output {motors = {-t, t, timeout = params.hold}}
    end
  end
end

return toroco.trigger(input.left, away), toroco.trigger(input.right, away)
