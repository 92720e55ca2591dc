"""The process shells: the zenoh side of the world, the agents and the teacher.

Each wraps a pure core in the bus (`bus`, `protocol`): `world_server` serves
`world_server.world.World` (`conag world`); `agent` runs one `agent_runtime.brain.Brain`
(`conag agent`) through `world_link` (liveliness, attach, sensor frames, commands),
`agent_feeds` (blueprint changes in, state reports out) and, for a learning student,
`student_link` (decisions out, reinforcements in); `teacher` answers students'
decisions with `teacher.core.Teacher` (`conag teacher`). Nothing below this layer
imports zenoh.
"""
