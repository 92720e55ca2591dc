"""The ConAg agent (paper §4): spatial maps, spreading activation, action selection.

`link` is the agent's end of the world connection (attach, frames, commands). The
cognitive core arrives with the agent issue (#3).
"""
