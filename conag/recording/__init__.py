"""Record, replay and echo the bus: the pure parts (no zenoh).

* `mcap_log`: bus messages to and from MCAP files (`McapRecorder`, `read_recording`);
* `replay`: when to re-publish each recorded message (`paced`), and the script that lets
  a live world in lockstep reproduce a recording (`LockstepScript`);
* `echo`: messages as text or JSON (`describe`), and the rate display (`RateMeter`).

The process shells that subscribe and publish are `conag/recording/recorder.py` and
`conag/recording/replayer.py`; the commands are `conag record`, `conag replay` and `conag echo`.
"""
