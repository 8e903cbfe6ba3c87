local toroco = require 'toroco'
toroco.configure_polling(toroco.device.p.value, 1, function(v) return v * 2 end)
toroco.run()
