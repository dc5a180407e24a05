"""Campaign feedback as one updating line, not 48 copies of "positioning 0.0 %"."""
import io

from hindrax_ident.progress_line import ProgressLine


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
