"""Where a world loop's wall time goes (issue 15): stepping, publishing, waiting for commands.

`LoopTimes` is filled in by the world server's loop (`nodes/world_server.py`) and written
by `conag world --profile PATH` (also `conag run --profile PATH`) when the world stops; the
scale benchmark (`bench/bench_scale.py`) reads it. Only ticks after the first are counted,
so waiting for agents to start and attach is not mistaken for waiting for their commands;
`first_tick` is the monotonic time (system-wide on Linux, comparable between processes)
at which the first tick's frames were out.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass


@dataclass
class LoopTimes:
    """Seconds of the loop's wall time, by what it was doing, over `ticks` ticks.

    `step`: `World.step`; `publish`: building, encoding and sending the sensor frames;
    `wait`: waiting for the agents' commands (and handling them as they come); `other`:
    statuses and views.
    """

    ticks: int = 0
    step: float = 0.0
    publish: float = 0.0
    wait: float = 0.0
    other: float = 0.0
    first_tick: float | None = None

    def per_tick_ms(self) -> dict[str, float]:
        """Milliseconds per tick of each part (empty before the second tick)."""
        if self.ticks == 0:
            return {}
        return {k: 1000.0 * getattr(self, k) / self.ticks for k in ("step", "publish", "wait", "other")}

    def as_dict(self) -> dict:
        """The figures and the per-tick milliseconds, for JSON."""
        return {**asdict(self), "per_tick_ms": self.per_tick_ms()}
