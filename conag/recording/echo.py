"""What `conag echo` prints: a message as text or JSON, and the rate of a stream of them.

`describe` decodes one sample's bytes with the protocol's codec and renders it as one
line (`key: Type(field=value, ...)`, long float tuples shortened) or as a JSON object
(`{"key": ..., "type": ..., "message": {...}}`, every field in full). Bytes that are not a
valid message are shown as such, never raised. `RateMeter` keeps the arrival times of the
last `window` messages (times from the clock the caller passes in) and reports their
rate and the spread of the gaps between them, as `ros2 topic hz` does.
"""

from __future__ import annotations

import itertools
import json
import math
from collections import deque
from dataclasses import asdict, dataclass

from protocol.codec import ProtocolError, decode

SHORT_TUPLE = 8  # float tuples longer than this are shortened in text lines


def describe(key: str, data: bytes, as_json: bool = False) -> str:
    """One line for a sample on `key` carrying `data` (see the module)."""
    try:
        msg = decode(data)
    except ProtocolError as exc:
        if as_json:
            return json.dumps({"key": key, "error": str(exc), "bytes": len(data)})
        return f"{key}: <not a ConAg message: {exc}; {len(data)} bytes>"
    name = type(msg).__name__
    fields = asdict(msg)  # type: ignore[call-overload]
    if as_json:
        return json.dumps({"key": key, "type": name, "message": fields})
    parts = ", ".join(f"{k}={_short(v)}" for k, v in fields.items())
    return f"{key}: {name}({parts})"


def _short(value: object) -> str:
    if isinstance(value, tuple) and len(value) > SHORT_TUPLE:
        head = ", ".join(_short(v) for v in value[:SHORT_TUPLE])
        return f"({head}, ... {len(value)} values)"
    if isinstance(value, float):
        return f"{value:.6g}"
    if isinstance(value, tuple):
        return "(" + ", ".join(_short(v) for v in value) + ("," if len(value) == 1 else "") + ")"
    return repr(value)


@dataclass(frozen=True)
class Rate:
    """The rate over the last messages: `hz`, and the gaps' min, max and standard deviation
    (seconds), over `window` gaps."""

    hz: float
    min_gap: float
    max_gap: float
    std_gap: float
    window: int

    def line(self) -> str:
        """The line `conag echo --hz` prints."""
        return (f"average rate: {self.hz:.3f} Hz  min: {self.min_gap:.4f}s max: {self.max_gap:.4f}s "
                f"std dev: {self.std_gap:.5f}s window: {self.window}")


class RateMeter:
    """Arrival times of the last `window` messages (see the module)."""

    def __init__(self, window: int = 1000):
        if window < 2:
            raise ValueError("the rate window must hold at least 2 messages")
        self._times: deque[float] = deque(maxlen=window)
        self.count = 0

    def add(self, t: float) -> None:
        """A message arrived at time `t` (seconds, from any monotonic clock)."""
        self._times.append(t)
        self.count += 1

    def rate(self) -> Rate | None:
        """The rate over the messages in the window; None before two have arrived."""
        times = list(self._times)
        if len(times) < 2:
            return None
        gaps = [b - a for a, b in itertools.pairwise(times)]
        mean = sum(gaps) / len(gaps)
        std = math.sqrt(sum((g - mean) ** 2 for g in gaps) / len(gaps))
        return Rate(1.0 / mean if mean > 0 else math.inf, min(gaps), max(gaps), std, len(gaps))
