-- /// wander: ahead for a while, then a turn of a random side and length ///
local toroco = require 'toroco.toroco'
local sched = require 'lumen.sched'
local params = toroco.params

math.randomseed(os.time())

return function()
  while true do
    toroco.set_output {motors = {params.speed, params.speed}}
    sched.sleep(1 + math.random() * 3)
    local t = params.turn
    if math.random(2) == 1 then
      toroco.set_output {motors = {t, -t}}
    else
      toroco.set_output {motors = {-t, t}}
    end
    sched.sleep(0.2 + math.random() * 0.6)
  end
end
