"""The ConAg agent (paper §4): spatial maps, spreading activation, action selection.

Pure core (no zenoh): `esm` (egocentric spatial maps), `spreading` (navigation maps),
`network` (the Fig. 8 construction network), `motivations`, `steering` and `brain` (one
decision step). Shell: `link` (the agent's end of the world connection) and `process`
(`conag agent`).
"""
