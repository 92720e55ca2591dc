"""Experiment report sections: each experiment script rewrites only its own section."""

from __future__ import annotations

import pytest

from experiments.report import write_section


def test_a_new_file_gets_the_header_and_the_section(tmp_path):
    doc = tmp_path / "E.md"
    write_section(doc, "G3", "## G3\nfirst")
    assert doc.read_text() == "# Experiments\n\n<!-- section:G3 -->\n## G3\nfirst\n<!-- /section:G3 -->\n"


def test_rewriting_a_section_keeps_the_others_and_their_order(tmp_path):
    doc = tmp_path / "E.md"
    write_section(doc, "R4", "## R4\nold")
    write_section(doc, "G3", "## G3\nold")
    write_section(doc, "L3", "## L3\nold")
    write_section(doc, "G3", "## G3\nnew\nlines")
    text = doc.read_text()
    assert "## G3\nnew\nlines" in text and "## G3\nold" not in text
    assert text.index("## R4") < text.index("## G3") < text.index("## L3")
    assert text.count("<!-- section:G3 -->") == 1


def test_a_section_without_its_end_marker_is_an_error_and_the_file_is_untouched(tmp_path):
    doc = tmp_path / "E.md"
    doc.write_text("# Experiments\n\n<!-- section:G3 -->\nhalf\n")
    with pytest.raises(ValueError, match="no closing marker"):
        write_section(doc, "G3", "new")
    assert doc.read_text() == "# Experiments\n\n<!-- section:G3 -->\nhalf\n"
