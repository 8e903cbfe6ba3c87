-- /// follower: the line between the two grey sensors ///
-- A sensor over the line means the robot drifted to the other side: it
-- turns toward that sensor until the line is between them again.
local toroco = require 'toroco.toroco'
local input = toroco.input
local params = toroco.params

local seen = {left = false, right = false}

local function steer()
  local v = params.straight
  if seen.left and not seen.right then
    v = params.left
  elseif seen.right and not seen.left then
    v = params.right
  end
  toroco.set_output {motors = {v[1], v[2]}}
end

return toroco.trigger(input.left, function(event, on_line)
  seen.left = on_line
  steer()
end), toroco.trigger(input.right, function(event, on_line)
  seen.right = on_line
  steer()
end)
