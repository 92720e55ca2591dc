"""The `conag` command line (`cli`, `layouts`) and the `conag run` supervisor (`run`).

The top layer: it starts and stops the processes of `nodes`, opens the bus through
`bus`, and runs `sim` for `conag render --agent-maps`; nothing imports it back.
"""
