"""The frame: stages in order on the device, options checked once, results, and ``collide()``."""
