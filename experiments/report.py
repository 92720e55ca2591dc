"""The experiments report (docs/results/experiments.md) is written by several experiment scripts; each owns one section.

A section sits between `<!-- section:KEY -->` and `<!-- /section:KEY -->` lines. Writing
it replaces only that span (or appends the section if the file lacks it), so re-running
one experiment never drops another's results.
"""

from __future__ import annotations

from pathlib import Path

# The results page the experiment scripts write their sections into (the docs site's).
RESULTS_DOC = Path(__file__).resolve().parent.parent / "docs" / "results" / "experiments.md"

HEADER = "# Experiments\n"


def _markers(key: str) -> tuple[str, str]:
    return f"<!-- section:{key} -->", f"<!-- /section:{key} -->"


def write_section(doc: str | Path, key: str, text: str) -> None:
    """Put `text` (markdown) into section `key` of `doc`, creating the file if needed."""
    doc = Path(doc)
    begin, end = _markers(key)
    block = f"{begin}\n{text.strip()}\n{end}\n"
    old = doc.read_text(encoding="utf-8") if doc.exists() else HEADER
    if begin in old:
        head, rest = old.split(begin, 1)
        if end not in rest:
            raise ValueError(f"{doc}: section {key!r} has no closing marker {end!r}")
        tail = rest.split(end, 1)[1].lstrip("\n")
        new = head + block + ("\n" + tail if tail else "")
    else:
        new = old.rstrip("\n") + "\n\n" + block
    doc.write_text(new, encoding="utf-8")
