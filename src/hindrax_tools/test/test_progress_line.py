"""Progress a person can follow: campaign feedback as one updating line, not 48 copies of "positioning 0.0 %"; a
long step (ident bag's fit, make ros-install's colcon) ticking its seconds on a terminal, named once in a log."""
import io
import sys
import threading

from hindrax_common.testing import wait_until
from hindrax_tools import progress_run
from hindrax_sim.progress_line import ProgressLine, Ticker
from hindrax_tools.results_doc import duration_rows, record_duration


def test_a_log_gets_each_state_once():
    lines: list[str] = []
    bar = ProgressLine(lines.append, tty=False)
    for text in ["positioning  progress   0.0 %"] * 48 + ["surge level 1/2 +5.00 N  progress  10.0 %"] * 3:
        bar.update(text)
    bar.line(">>> attach the ballast")
    assert lines == ["positioning  progress   0.0 %", "surge level 1/2 +5.00 N  progress  10.0 %",
                     ">>> attach the ballast"]


def test_a_terminal_gets_one_line_rewritten_in_place():
    out: list[str] = []
    term = io.StringIO()
    bar = ProgressLine(out.append, stream=term, tty=True)
    for p in (0.0, 0.0, 12.5, 25.0):
        bar.update(f"surge  progress {p:5.1f} %")
    bar.line("campaign finished")
    assert term.getvalue() == ("\rsurge  progress   0.0 %\x1b[K\rsurge  progress  12.5 %\x1b[K"
                               "\rsurge  progress  25.0 %\x1b[K\n")
    assert out == ["campaign finished"]


class _Clock:
    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t


def test_a_ticker_rewrites_its_seconds_on_a_terminal_and_names_each_step_once_in_a_log():
    clock, term = _Clock(), io.StringIO()
    with Ticker(ProgressLine(stream=term, tty=True), "ident bag: fitting", period_s=3600.0, clock=clock) as t:
        clock.t += 42.4
        t.show()                                                  # what the thread does every period
        t.set("ident bag: writing")
    assert term.getvalue() == ("\rident bag: fitting  0 s\x1b[K\rident bag: fitting  42 s\x1b[K"
                               "\rident bag: writing  42 s\x1b[K\n")
    lines: list[str] = []
    with Ticker(ProgressLine(lines.append, tty=False), "ident bag: fitting", clock=clock) as t:
        clock.t += 50.0
        t.show()
        t.set("ident bag: writing")
    assert lines == ["ident bag: fitting", "ident bag: writing"]


def test_a_ticker_on_a_terminal_ticks_by_itself():
    ticked = threading.Event()

    class Stream(io.StringIO):
        def write(self, s):
            if s.count("\r") and self.getvalue().count("\r") >= 1:
                ticked.set()
            return super().write(s)

    with Ticker(ProgressLine(stream=Stream(), tty=True), "colcon", period_s=0.01):
        assert ticked.wait(30.0)


def test_progress_run_shows_what_colcon_builds_and_how_long_it_took():
    lines: list[str] = []
    colcon = ("import sys; print('Starting >>> hindrax_msgs'); print('Starting >>> hindrax_drivers');"
              "print('Finished <<< hindrax_drivers [1.2s]'); print('Finished <<< hindrax_msgs [3min 1s]');"
              "print('Summary: 2 packages finished [3min 2s]')")
    code, seconds = progress_run.run("ros-install", [sys.executable, "-c", colcon], ProgressLine(lines.append,
                                                                                                 tty=False))
    assert code == 0 and seconds >= 0.0
    states = [x for x in lines if x.startswith("ros-install: ")]
    assert states[:5] == ["ros-install: starting", "ros-install: running",
                          "ros-install: building hindrax_msgs (0 finished)",
                          "ros-install: building hindrax_msgs, hindrax_drivers (0 finished)",
                          "ros-install: building hindrax_msgs (1 finished)"]
    assert "Summary: 2 packages finished [3min 2s]" in lines and states[-1].startswith("ros-install: finished in ")
    code, _ = progress_run.run("ros-install", [sys.executable, "-c", "raise SystemExit(3)"],
                               ProgressLine(lines.append, tty=False))
    assert code == 3 and lines[-1].startswith("ros-install: FAILED (exit 3) in ")


def test_progress_run_records_a_successful_build_in_the_durations_section(tmp_path):
    doc = tmp_path / "results.md"
    record_duration(doc, "make setup (new .venv)", 211.0)
    assert progress_run.main(["ros-install", "--results-doc", str(doc), "--record", "make ros-install", "--",
                              sys.executable, "-c", "pass"]) == 0
    rows = duration_rows(doc.read_text())
    assert set(rows) == {"make setup (new .venv)", "make ros-install"}
    assert rows["make setup (new .venv)"][1:3] == ["211", "3.5"]
    assert progress_run.main(["ros-install", "--results-doc", str(doc), "--record", "make failed", "--",
                              sys.executable, "-c", "raise SystemExit(1)"]) == 1
    assert "make failed" not in duration_rows(doc.read_text())


def test_a_ticker_in_a_log_repeats_its_step_with_the_seconds_so_no_silence_is_long():
    """Issue 74.6: a fit's log stayed silent 142 s; off a terminal the step now comes again every quiet_s."""
    lines: list[str] = []
    with Ticker(ProgressLine(lines.append, tty=False), "run: fitting", quiet_s=0.01):
        wait_until(lambda: len(lines) >= 3, 30.0, message="the ticker's repeated lines")
    assert lines[0] == "run: fitting"
    assert all(line.startswith("run: fitting (") and line.endswith(" s)") for line in lines[1:3]), lines
