"""The ConAg world (paper §3): a pymunk world of discs and agent bodies, and its server.

`world.World` is the pure core (physics, sensors, gripper, perturbation; no bus);
`server.WorldServer` is the thin zenoh shell around it.
"""
