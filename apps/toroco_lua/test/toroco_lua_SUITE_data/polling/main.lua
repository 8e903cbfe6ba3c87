-- The original's configure_polling: p can be polled, s emits by itself.
local toroco = require 'toroco'
toroco.configure_polling(toroco.device.p.value, 0.02)
toroco.configure_polling(toroco.device.s.value, 0.5)
toroco.run()
