local toroco = require 'toroco'
toroco.run(
