-- lumen's sched.sleep on the runtime's clock: ticks every 0.05 s.
local toroco = require 'toroco'
local sched = require 'lumen.sched'

return function()
  local n = 0
  while true do
    n = n + 1
    toroco.send_output {tick = {n}}
    sched.sleep(0.05)
  end
end
