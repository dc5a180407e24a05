"""Issue 45.6: `make setup` shows its progress as ONE line updated in place on a terminal (2-3 silent minutes
before), and a line per step in a log. The functions live in scripts/progress.sh, which scripts/setup_venv.sh
sources; here they run alone in bash, under a pseudo-terminal and into a pipe."""
from __future__ import annotations

import os
import pty
import re
import select
import subprocess
import termios
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PROGRESS = ROOT / "scripts" / "progress.sh"
#: two steps; the first one ticks until this test answers on stdin (after it has seen a tick)
SCRIPT = f"""STEPS=2
source {PROGRESS}
step one
ticking
read -r _
stop_ticking
step two
progress_done
echo after
"""
UPDATE = re.compile(r"setup \[(\d)/2\] (one|two)  (\d+)s\x1b\[K")


def test_a_terminal_gets_one_line_rewritten_at_each_step_and_tick():
    master, slave = pty.openpty()
    attrs = termios.tcgetattr(slave)
    attrs[3] &= ~termios.ECHO  # the answer on stdin is not echoed into the output read here
    termios.tcsetattr(slave, termios.TCSANOW, attrs)
    p = subprocess.Popen(["bash", "-c", SCRIPT], stdin=slave, stdout=slave, stderr=slave, cwd=ROOT, close_fds=True)
    os.close(slave)
    out = b""

    def read_until(cond, timeout_s: float) -> None:
        nonlocal out
        deadline = time.monotonic() + timeout_s
        while not cond(out.decode(errors="replace")) and time.monotonic() < deadline:
            if select.select([master], [], [], 0.5)[0]:
                try:
                    out += os.read(master, 4096)
                except OSError:  # EIO: the child closed the terminal
                    break

    try:
        # the first step's line, then at least one tick of it (every 2 s; generous for a loaded machine)
        read_until(lambda s: s.count("\rsetup [1/2] one") >= 2, 60)
        os.write(master, b"\n")
        read_until(lambda s: "after" in s and s.endswith("\n"), 60)
        assert p.wait(30) == 0
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
        os.close(master)
    text = out.decode()
    progress, _, rest = text.partition("\r\n")  # the terminal turns the one newline into CR LF
    assert rest == "after\r\n", repr(text)
    assert "\n" not in progress, repr(text)  # every update before it stays on the one line
    updates = progress.split("\r")
    assert updates[0] == "", repr(text)  # each update starts at the line's beginning ...
    parsed = [UPDATE.fullmatch(u) for u in updates[1:]]
    assert all(parsed), repr(text)  # ... and erases what a longer earlier text left
    steps = [(m.group(1), m.group(2)) for m in parsed]
    assert steps[0] == ("1", "one") and steps[-1] == ("2", "two"), steps
    assert steps.count(("1", "one")) >= 2 and steps.count(("2", "two")) == 1, steps  # ticked, then the next step
    seconds = [int(m.group(3)) for m in parsed]
    assert seconds == sorted(seconds) and seconds[1] >= 2, seconds  # the tick shows the elapsed time, 2 s on


def test_a_log_gets_one_line_per_step_and_no_ticks():
    res = subprocess.run(["bash", "-c", SCRIPT], input="\n", capture_output=True, text=True, cwd=ROOT, timeout=60)
    assert res.returncode == 0, res.stderr
    assert res.stdout == "setup [1/2] one\nsetup [2/2] two\nafter\n"


def test_the_setup_script_reports_every_step_through_it():
    """setup_venv.sh sources the progress functions, counts its steps right (the last one reads [5/5]) and ticks
    through the pip install and the interfaces' build, the two long steps."""
    text = (ROOT / "scripts" / "setup_venv.sh").read_text()
    assert "source scripts/progress.sh" in text
    steps = re.findall(r'^step "', text, re.MULTILINE)
    assert re.search(rf"^STEPS={len(steps)}$", text, re.MULTILINE), len(steps)
    assert text.count("\nticking\n") == 2 and "progress_done" in text
    assert "scripts/progress.sh" in (ROOT / "Makefile").read_text()  # a change to it re-runs `make setup`
