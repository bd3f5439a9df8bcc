"""Foreign Kheperas: robots the project's simulator does not describe, drawn from a seed.

Written apart from what fits a simulator to a robot: nothing here imports
``khepera_noise_ros.gap``, ``khepera_noise_ros.reality.effects``,
``khepera_noise_ros.reality.world`` or a simulator-side effect model.  It uses the core
(task, network, evolution) and the serial plumbing (``KheperaRobots``, the pty server),
so that its robots are driven exactly as the emulated robot is (docs/foreign-robots.md).
"""
