"""What every package of the stack shares, and nothing that would tie it to one robot's world.

``params`` (config files and dataclasses), ``types`` (the data crossing the hardware seam and the
setpoint interface), ``conversions`` (messages <-> those types), ``topics`` (names and QoS),
``node_runtime`` (``main()`` of every node executable), ``rotations``, and the torque arms' descriptions
(``arm_description``, ``panda_description``, ``xarm_description``).
No pybullet, no torch: the bridge, the simulator and the learner all import this package, and
nothing here imports them.
"""
