"""Where a world loop's wall time goes (issue 15): stepping, publishing, waiting for commands.

`LoopTimes` is filled in by the world server's loop (`world_server/server.py`) and written
by `conag world --profile PATH` (also `conag run --profile PATH`) when the world stops; the
scale benchmark (`bench/bench_scale.py`) reads it. Only ticks after the first are counted,
so waiting for agents to start and attach is not mistaken for waiting for their commands;
Commands are counted with how far their frame was behind the world when they came
(`command`). `first_tick` is the monotonic time (system-wide on Linux, comparable between processes)
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
    commands: int = 0        # commands taken (after the first tick)
    stale_commands: int = 0  # of those, answering a frame more than one tick old when they came
    max_lag: int = 0         # the most ticks a command's frame was behind the world when it came
    counting: bool = False   # past the first tick (and in realtime, a warm-up): the figures count
    _count_from: int | None = None  # the first tick that counts, once known

    def command(self, lag: int) -> None:
        """A command came answering the frame of `lag` ticks ago (0: the newest frame).

        In realtime mode the world does not wait: an agent slower than a tick answers an
        older frame, and one that answers a frame more than a tick old lags behind."""
        if not self.counting:
            return
        self.commands += 1
        self.stale_commands += lag > 1
        self.max_lag = max(self.max_lag, lag)

    def tick_done(self, tick: int, everyone_there: bool, warmup: int, now: float, *, wait: float, step: float,
                  publish: float) -> None:
        """Tick `tick` is out at monotonic time `now`: how long the loop waited before it,
        stepped and published. `everyone_there`: all awaited agents have attached; `warmup`:
        ticks after that not counted (realtime)."""
        if self._count_from is None:
            if everyone_there:
                self.first_tick = now
                self._count_from = tick + 1 + warmup
            return
        if tick >= self._count_from:
            self.counting = True
            self.ticks += 1
            self.wait += wait
            self.step += step
            self.publish += publish

    def other_done(self, seconds: float) -> None:
        """Time spent after a tick on statuses and views."""
        if self.counting:
            self.other += seconds

    def per_tick_ms(self) -> dict[str, float]:
        """Milliseconds per tick of each part (empty before the second tick)."""
        if self.ticks == 0:
            return {}
        return {k: 1000.0 * getattr(self, k) / self.ticks for k in ("step", "publish", "wait", "other")}

    def as_dict(self) -> dict:
        """The figures and the per-tick milliseconds, for JSON."""
        figures = {k: v for k, v in asdict(self).items() if not k.startswith("_")}
        return {**figures, "per_tick_ms": self.per_tick_ms()}
