local toroco = require 'toroco'

toroco.configure_polling(toroco.device.p.nope, 1)
