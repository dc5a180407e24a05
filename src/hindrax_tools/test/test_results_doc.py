"""docs/results.md sections are replaced one at a time, atomically, and never by a test run by accident."""
from __future__ import annotations

import json
import subprocess

import pytest

from hindrax_common.testing import child_env, python_executable
from hindrax_tools.results_doc import ResultsDocError, markdown_table, write_section


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


def test_a_full_run_removes_the_partial_runs_it_supersedes(tmp_path):
    """``make bench`` (section ``bench``, prefix ``bench-``) removes the sections of earlier ``--only`` runs and
    nothing else: the scenario table, the text between sections and a section named ``benchmarks`` stay."""
    doc = tmp_path / "results.md"
    write_section(doc, "bench-stack-actuation", "Benchmarks: stack, actuation", "stale 72 %", "bench --only")
    write_section(doc, "scenarios", "Scenario suite", "table A", "hindrax ident scenarios")
    write_section(doc, "bench-safety", "Benchmarks: safety", "stale safety", "bench --only safety")
    write_section(doc, "benchmarks", "Other", "unrelated", "x")
    write_section(doc, "bench", "Benchmarks", "full 39 %", "make bench", supersedes_prefix="bench-")
    text = doc.read_text()
    assert "stale" not in text and "bench-safety" not in text and "bench-stack-actuation" not in text
    assert "full 39 %" in text and "table A" in text and "unrelated" in text
    assert "\n\n\n" not in text and text.endswith("\n")
    write_section(doc, "bench-safety", "Benchmarks: safety", "new partial", "bench --only safety")
    write_section(doc, "bench", "Benchmarks", "full again", "make bench")  # no prefix: partials kept
    assert "new partial" in doc.read_text()


def test_a_partial_run_takes_its_rows_out_of_the_full_table(tmp_path):
    """``bench --only stack`` after ``make bench``: the full table keeps every row but the stack's, and says once
    which section holds them now; a second partial run does not repeat the line; rows of other benchmarks, a
    measure that contains the word and the scenario table stay."""
    doc = tmp_path / "results.md"
    full = markdown_table(["benchmark", "measure", "value"], [["stack", "launch_running_cpu_total", "26.48"],
                                                              ["safety", "stack_kill_s", "0.2"],
                                                              ["i2c", "stack", "1"]])
    write_section(doc, "bench", "Benchmarks (`make bench`)", full, "make bench", supersedes_prefix="bench-")
    write_section(doc, "scenarios", "Scenario suite", "| stack | table A |", "hindrax ident scenarios")
    newer = markdown_table(["benchmark", "measure", "value"], [["stack", "launch_running_cpu_total", "50.85"]])
    for _ in range(2):
        write_section(doc, "bench-stack", "Benchmarks: stack", newer, "bench --only stack",
                      supersedes_rows=("bench", ["stack"]))
    text = doc.read_text()
    bench = text[text.index("<!-- results:bench:begin -->"):text.index("<!-- results:bench:end -->")]
    assert "26.48" not in text and "50.85" in text
    assert "| safety | stack_kill_s | 0.2 |" in bench and "| i2c | stack | 1 |" in bench
    assert bench.count('superseded by the newer section "Benchmarks: stack"') == 1
    assert "| stack | table A |" in text


def test_a_broken_superseded_section_writes_nothing(tmp_path):
    doc = tmp_path / "results.md"
    original = "# R\n<!-- results:bench-old:begin -->\nhalf a section\n"
    doc.write_text(original)
    with pytest.raises(ResultsDocError, match="bench-old"):
        write_section(doc, "bench", "Benchmarks", "z", "make bench", supersedes_prefix="bench-")
    assert doc.read_text() == original


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


def test_bench_writes_its_section_only_when_asked(tmp_path):
    """``python -m hindrax_tools.bench --results-doc PATH`` writes the rows of its
    results.json into PATH's section,
    names the command, and leaves the other sections alone; without the option it writes no document."""
    doc = tmp_path / "results.md"
    write_section(doc, "scenarios", "Scenario suite", "| a |\n|---|\n| kept |", "hindrax ident scenarios")
    cmd = [python_executable(), "-m", "hindrax_tools.bench", "--only", "cli", "--quick",
           "--out", str(tmp_path / "b")]
    r = subprocess.run(cmd + ["--results-doc", str(doc)], env=child_env(), capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    text = doc.read_text()
    assert "| kept |" in text  # the other section survives
    section = text[text.index("<!-- results:bench-cli:begin -->"):text.index("<!-- results:bench-cli:end -->")]
    assert "`python -m hindrax_tools.bench --only cli --quick" in section
    rows = json.loads((tmp_path / "b" / "results.json").read_text())["rows"]
    assert rows and all(f"| cli | {row['name']} | " in section for row in rows)
    other = tmp_path / "untouched.md"
    r = subprocess.run(cmd, env=child_env(), capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert r.returncode == 0 and not other.exists() and "results: section" not in r.stdout
