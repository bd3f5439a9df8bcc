"""The paper's experiment (section 4): settings, the five-step protocol, statistics,
figures and the report, run by ``khepera-noise replicate``.

Nothing here imports ROS: the protocol takes its evaluators from the caller
(the command wires them to the node graph, the hardware bridge or the core).
"""
