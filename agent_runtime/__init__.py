"""The ConAg agent (paper §4): spatial maps, spreading activation, action selection.

Pure core (no zenoh): `esm` (egocentric spatial maps), `spreading` (navigation maps),
`matching` (goal sequencing, paper §6), `far_memory`, `network` (the Fig. 8 construction
network), `learning` (the student network of §5.1 and its delta rule), `qlearning`,
`motivations`, `steering` and `brain` (one decision step). Its process shell is
`nodes.agent` (`conag agent`), with `nodes.world_link`, `nodes.agent_feeds` and
`nodes.student_link`; `sim` runs brains in one process with the world core.
"""
