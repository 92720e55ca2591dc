"""In-process runs: the world core and one Brain per agent in one process, no bus.

The layer above the pure cores, beside the process shells: the same World and
Brain code as the processes, stepped in lockstep, for tests, experiments and pictures.
`conag run` is the real thing: one process per agent.

* `loop`: the one simulation loop: `start` a run, `SimRun.run` it until complete, out
  of ticks, stalled (`world_server.stall`) or a stop condition says so, with per-tick
  observers (`FirstCompletion`); it returns a `SimResult`;
* `trials`: the learning trials of paper §5.1 (Fig. 9) on that loop;
* `render_agent`: one agent's maps beside the world (`conag render --agent-maps`).
"""

from conag.sim.loop import FirstCompletion, Observer, SimResult, SimRun, StopCondition, start

__all__ = ["FirstCompletion", "Observer", "SimResult", "SimRun", "StopCondition", "start"]
