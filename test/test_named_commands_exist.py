"""Every ``hindrax X`` a message names is a command of the CLI (issue 74.1).

A disarm cause's next step ("then hindrax reset, hindrax arm"), a refusal ("clear it with hindrax reset") or a hint
("check with hindrax health") that names a command the CLI does not have leaves the operator with nothing to type:
the topside said "then hindrax reset" while there was no ``hindrax reset``. Every string literal of the two packages'
sources (docstrings aside) is read with :mod:`ast`; each ``hindrax <word> [<word>]`` in it must be a command of
:data:`hindrax_tools.cli.COMMANDS`, a group followed by one of its commands, or a group's name as the prefix of
an error line (``hindrax sros2: ...``).
"""
from __future__ import annotations

import ast
import re
from pathlib import Path

from hindrax_bringup.supervisor.disarm_cause import _NEXT_STEPS, _DEFAULT_STEP, _TRIP_STEP
from hindrax_tools.cli import COMMANDS

SRC = Path(__file__).resolve().parents[1] / "src"
#: "hindrax <word>" phrases that name no command: a device's boot banner, a diagnostic hardware id
NOT_COMMANDS = {"hindrax emulator", "hindrax identification"}
_NAMED = re.compile(r"hindrax ([a-z][a-z0-9-]*)(?: ([a-z][a-z0-9-]*))?(:?)")


def _messages(path: Path):
    tree = ast.parse(path.read_text())
    docstrings = {id(n.body[0].value) for n in ast.walk(tree)
                  if isinstance(n, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef))
                  and n.body and isinstance(n.body[0], ast.Expr) and isinstance(n.body[0].value, ast.Constant)}
    for node in ast.walk(tree):
        if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docstrings:
            yield node.value


def unknown_commands(text: str) -> list[str]:
    """The ``hindrax ...`` phrases of ``text`` that name no command of the CLI."""
    paths = {words for words, _module, _help in COMMANDS}
    groups = {words[:i] for words in paths for i in range(1, len(words))}
    bad = []
    for m in _NAMED.finditer(text):
        first, second, colon = m.groups()
        if first == "hindrax":  # "docker exec hindrax hindrax thruster-test": the container, then the command
            first, second = second, None
        ok = ((first,) in paths or ((first,) in groups and ((first, second) in paths or (colon and not second)))
              or m.group(0).rstrip(":") in NOT_COMMANDS)
        if not ok:
            bad.append(m.group(0))
    return bad


def test_the_check_knows_a_missing_command():
    assert unknown_commands("then hindrax reboot, hindrax arm") == ["hindrax reboot"]
    assert unknown_commands("hindrax ident frobnicate") == ["hindrax ident frobnicate"]
    assert unknown_commands("hindrax ident start; hindrax sros2: no sros2; hindrax config check") == []


def test_every_disarm_cause_names_commands_that_exist():
    steps = [step for _words, step in _NEXT_STEPS] + [_TRIP_STEP, _DEFAULT_STEP]
    assert any("hindrax reset" in s for s in steps)
    assert [bad for s in steps for bad in unknown_commands(s)] == []


def test_every_message_of_the_sources_names_commands_that_exist():
    bad = [f"{path.relative_to(SRC)}: {phrase}"
           for package in ("hindrax_common/hindrax_common", "hindrax_drivers/hindrax_drivers",
                           "hindrax_bringup/hindrax_bringup", "hindrax_onboard/hindrax_onboard",
                           "hindrax_fit/hindrax_fit", "hindrax_sim/hindrax_sim", "hindrax_tools/hindrax_tools")
           for path in sorted((SRC / package).rglob("*.py"))
           for text in _messages(path) for phrase in unknown_commands(text)]
    assert bad == []
