-- /// display: shows the count ///
local toroco = require 'toroco.toroco'

return toroco.trigger(toroco.input.count, function(event, n)
  toroco.send_output {signal = {'count', n}}
end)
