-- A coroutine that waits for `go', then for `more' at most 0.2 s.
local toroco = require 'toroco.toroco'
local input = toroco.input

return function()
  while true do
    local v = toroco.wait_for_input(input.go)
    toroco.send_output {got = {v}}
    local w = toroco.wait_for_input(input.more, 0.2)
    if w == nil then
      toroco.send_output {timeout = {v}}
    else
      toroco.send_output {more = {w}}
    end
  end
end
