"""A Franka arm (FR3) as a robot plugin of the bridge, through libfranka (``franky``):
``robot:=franka``. It imports no simulator; franky-sim's FR3 to rehearse it on is
``franka_sim_node``."""
