"""The ConAg agent (paper §4): spatial maps, spreading activation, action selection.

Pure core (no zenoh): `esm` (egocentric spatial maps), `spreading` (navigation maps),
`matching` (goal sequencing, paper §6), `far_memory`, `network` (the Fig. 8 construction
network), `learning` (the student network of §5.1 and its delta rule), `qlearning`,
`motivations`, `steering` and `brain` (one decision step). Its process shell is
`agent_runtime.node` (`conag agent`), with `agent_runtime.world_link`, `agent_runtime.feeds` and
`agent_runtime.student_link`; `conag.sim` runs brains in one process with the world core.
"""
