"""The results pages' pictures are made, not committed: `python3 -m experiments.pictures`
draws each one the pages link, from the committed results."""

from __future__ import annotations

import re

from experiments import pictures
from tests.conftest import ROOT

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def test_every_picture_the_results_pages_link_is_one_the_command_draws():
    linked = set()
    for page in (ROOT / "docs").rglob("*.md"):
        linked |= set(re.findall(r"\]\((?:\.\./)+experiments/([\w-]+)\.png\)", page.read_text(encoding="utf-8")))
    assert linked and linked <= set(pictures.PICTURES), linked - set(pictures.PICTURES)


def test_a_picture_kept_as_data_is_drawn_from_it(tmp_path):
    written = pictures.draw(["lattice_learning"], tmp_path)  # from experiments/lattice_learning.json
    assert [p.name for p in written] == ["lattice_learning.png"]
    assert written[0].read_bytes().startswith(PNG_SIGNATURE)
    assert "lattice_learning" not in pictures.missing(tmp_path) and "fig9_learning" in pictures.missing(tmp_path)
