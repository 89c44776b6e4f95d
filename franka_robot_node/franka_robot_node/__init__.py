"""A Franka arm (FR3) as a robot plugin of the bridge, through libfranka (``franky``), and
franky-sim's MuJoCo FR3 to rehearse it on: ``robot:=franka``, ``franka_sim``."""
