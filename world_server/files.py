"""Files other processes read while they are written: whole or not at all.

A process that is killed, or a disk that fills, halfway through a plain write leaves half a
file, which a reader then takes for the whole (`conag run` read an empty world summary).
`write_text_whole` writes a temporary file beside the target and renames it into place: a
reader finds the old file or the new one, never a part, and two writers at once each
replace it whole.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path


def write_text_whole(path: str | Path, text: str) -> None:
    """Write `text` to `path` through a temporary file renamed into place (see the module);
    on any error the file there is untouched and the temporary file removed."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="") as f:
            f.write(text)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
