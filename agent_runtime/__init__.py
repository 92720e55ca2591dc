"""The ConAg agent (paper §4): spatial maps, spreading activation, action selection.

Pure core (no zenoh): `esm` (egocentric spatial maps), `spreading` (navigation maps),
`network` (the Fig. 8 construction network), `learning` (the student network of §5.1 and
its delta rule), `qlearning`, `motivations`, `steering` and `brain` (one decision step).
Shell: `link` (the agent's end of the world connection), `student_link` (its end of the
teacher's) and `process` (`conag agent`).
"""
