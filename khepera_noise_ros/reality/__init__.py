"""Reality: the Khepera's serial protocol, the robot emulator that stands in for the physical
robot, and the hardware bridge's backend.

``serial_protocol`` formats and strictly parses the robot's ASCII commands; ``effects`` are
the physical processes the emulated robot has and the simulator does not model (configured
from YAML, names from the effect vocabulary); ``world`` is the emulated world, pure numpy;
``emulator`` serves it on pseudo-terminals; ``khepera_robot`` runs the light-centring episode
on robots over serial ports (or in-process over a world).  Nothing here uses the simulator's
noise model (``core.noise``).
"""
