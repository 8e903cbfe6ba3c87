-- Requires a module of the program's folder, not of its own.
local toroco = require 'toroco.toroco'
local lib = require 'lib.twice'

return toroco.trigger(toroco.input.value, function(event, v)
  toroco.send_output {twice = {lib.twice(v)}}
end)
