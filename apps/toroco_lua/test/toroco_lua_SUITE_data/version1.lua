local toroco = require 'toroco'
return toroco.trigger(toroco.input.ask, function(event, v) toroco.send_output {answer = {'v1', v}} end)
