"""docs/results.md sections are replaced one at a time, atomically, and never by a test run by accident."""
from __future__ import annotations

import pytest

from hindrax_ident.results_doc import ResultsDocError, markdown_table, write_section


def test_sections_are_created_replaced_and_kept_apart(tmp_path):
    doc = tmp_path / "results.md"
    write_section(doc, "bench", "Benchmarks", "old bench", "make bench")
    write_section(doc, "scenarios", "Scenario suite", "table A", "hindrax ident scenarios")
    write_section(doc, "bench", "Benchmarks", "new bench", "make bench")
    text = doc.read_text()
    assert text.startswith("# Measured results")
    assert "new bench" in text and "old bench" not in text
    assert "table A" in text
    assert text.count("<!-- results:bench:begin -->") == 1
    # order kept: bench was written first, so it stays before the scenarios section
    assert text.index("new bench") < text.index("table A")
    assert "Written by `make bench`" in text


def test_text_outside_the_sections_is_kept(tmp_path):
    doc = tmp_path / "results.md"
    doc.write_text("# Measured results\n\nHand-written intro.\n")
    write_section(doc, "control", "Control", "x", "hindrax control evaluate")
    write_section(doc, "control", "Control", "y", "hindrax control evaluate")
    text = doc.read_text()
    assert "Hand-written intro." in text and text.rstrip().endswith("<!-- results:control:end -->")
    assert "\ny\n" in text and "\nx\n" not in text


def test_broken_markers_write_nothing(tmp_path):
    doc = tmp_path / "results.md"
    original = "# R\n<!-- results:bench:end -->\nkeep me\n<!-- results:bench:begin -->\n"
    doc.write_text(original)
    with pytest.raises(ResultsDocError, match="broken pair of markers"):
        write_section(doc, "bench", "Benchmarks", "z", "make bench")
    assert doc.read_text() == original
    assert [p.name for p in tmp_path.iterdir()] == ["results.md"]  # no temporary file left


def test_bad_name_and_missing_folder(tmp_path):
    with pytest.raises(ResultsDocError, match="allowed"):
        write_section(tmp_path / "r.md", "Bad Name", "t", "b", "c")
    with pytest.raises(FileNotFoundError):
        write_section(tmp_path / "nope" / "r.md", "bench", "t", "b", "c")


def test_markdown_table_escapes_pipes():
    assert markdown_table(["a", "b"], [[1, "x|y"]]).splitlines() == ["| a | b |", "|---|---|", "| 1 | x\\|y |"]
