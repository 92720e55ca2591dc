"""The ConAg world (paper §3): a pymunk world of discs and agent bodies.

Pure core (no bus): `world.World` (physics, sensors, gripper, perturbation), the
scenario files, the layout generator and buildability check, pictures (`render`), and
what a run reports (`stall`, `summary`). Its process shell, the zenoh server around
`World`, is `world_server.server.WorldServer` (`conag world`).
"""
