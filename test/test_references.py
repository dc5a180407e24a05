"""The repository carries its own references (docs/architecture.md §3, "Citations").

* No tracked text file points to a document outside the repository: the project's former shared notes
  (by name), a shared folder next to the clone, or an absolute path on a development machine.
* Every ``docs/<name>.md §N`` cited anywhere resolves to a numbered heading of that file, and every
  ``docs/<name>.md`` cited exists.
* A paper is cited by its key from docs/references.md only, never by a project-internal number.
* docs/architecture.md describes today's design in at most 500 lines (the history of a decision belongs in the
  body of its commit).

The forbidden names are assembled from parts so that this file does not match a plain grep for them.
"""
from __future__ import annotations

import re
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
THIS = Path(__file__).resolve()

_MD = "." + "md"
#: Notes that lived outside the repository; their content is now in docs/ (same section numbers).
OUTSIDE_NOTES = tuple(stem + _MD for stem in ("hardware", "hydrodynamics", "design", "ros2-pip"))

FORBIDDEN = [
    (re.compile(r"(?<![\w-])(?:" + "|".join(re.escape(n) for n in OUTSIDE_NOTES) + r")\b"),
     "a note outside the repository"),
    (re.compile(r"\.\./" + "shared" + r"\b|\b" + "shared" + r"/(?:reference|seeds)\b"), "the shared folder"),
    (re.compile("/" + "work" + "/"), "an absolute path of a development machine"),
    (re.compile(r"(?<![\w.])/(?:home|root|Users)/[\w.-]+/"), "an absolute path to a home directory"),
    (re.compile("/" + "tmp" + "/hx" + r"\b"), "a helper's scratch path"),
]

#: Seed numbers and the keys of docs/references.md that must accompany them.
PAPER_KEYS = ("[Hindrax-AM]", "[NTNU-Thesis]", "[Hindrax-Drag]", "[SmallROV]")

_ID = r"\d+(?:\.\d+)*(?:\.[A-Z](?![A-Za-z]))?"
_CITE = re.compile(r"(?<![\w/.-])docs/([\w-]+\.md)")  # not another repository's .../docs/x.md
_FIRST = re.compile(r"\s?§\s?(" + _ID + r")")
_NEXT = re.compile(r"(?:[a-z](?![a-z]))?(?:\s*(?:,|and|or)\s*§\s?|\s*[-–]\s*§?\s?)(" + _ID + r")")
_HEADING = re.compile(r"^#{1,6}\s+(" + _ID + r")\.?(?:\s|$)")


def _tracked_files() -> list[Path]:
    try:
        out = subprocess.run(["git", "-C", str(ROOT), "ls-files", "-z"], capture_output=True, check=True,
                             timeout=60).stdout.decode()
        names = [n for n in out.split("\0") if n]
    except (OSError, subprocess.SubprocessError):  # not a git checkout (e.g. a source archive)
        skip = {".git", ".venv", "build", "install", "log", "runs", "__pycache__"}
        names = [str(p.relative_to(ROOT)) for p in ROOT.rglob("*")
                 if p.is_file() and not (set(p.relative_to(ROOT).parts) & skip)]
    return [ROOT / n for n in names]


def _text_files() -> dict[Path, str]:
    texts = {}
    for path in _tracked_files():
        if path.resolve() == THIS or not path.is_file():
            continue
        data = path.read_bytes()
        if b"\0" in data[:8192]:
            continue  # binary (MCAP bags and the like)
        try:
            texts[path] = data.decode("utf-8")
        except UnicodeDecodeError:
            continue
    return texts


@pytest.fixture(scope="module")
def texts() -> dict[Path, str]:
    found = _text_files()
    assert len(found) > 50, f"only {len(found)} tracked text files found under {ROOT}"
    return found


def _where(path: Path, text: str, pos: int) -> str:
    line_no = text.count("\n", 0, pos) + 1
    line = text.splitlines()[line_no - 1].strip()
    return f"{path.relative_to(ROOT)}:{line_no}: {line[:140]}"


def cited_sections(text: str) -> list[tuple[int, str, str]]:
    """(position, docs file name, section id) of every ``docs/<name>.md §N`` in ``text``; ranges and lists
    (``§1.2-§1.5``, ``§3.4-3.7``, ``§2, §6``, ``§3.1 and §3.8``) give one entry per id."""
    found = []
    for m in _CITE.finditer(text):
        pos = m.end()
        first = _FIRST.match(text, pos)
        if not first:
            found.append((m.start(), m.group(1), ""))
            continue
        found.append((m.start(), m.group(1), first.group(1)))
        pos = first.end()
        while (nxt := _NEXT.match(text, pos)) is not None:
            found.append((m.start(), m.group(1), nxt.group(1)))
            pos = nxt.end()
    return found


def headings(doc: Path) -> set[str]:
    """Section ids of the numbered headings of a markdown file (``## 1.3.1 ...`` -> ``1.3.1``)."""
    ids = set()
    for line in doc.read_text(encoding="utf-8").splitlines():
        m = _HEADING.match(line)
        if m:
            ids.add(m.group(1))
    return ids


def test_no_reference_outside_the_repository(texts: dict[Path, str]) -> None:
    bad = []
    for path, text in texts.items():
        for pattern, what in FORBIDDEN:
            for m in pattern.finditer(text):
                bad.append(f"{_where(path, text, m.start())}  <- {what}")
    assert not bad, "references to documents outside the repository:\n" + "\n".join(bad)


def test_every_cited_docs_section_exists(texts: dict[Path, str]) -> None:
    cache: dict[str, set[str] | None] = {}
    bad = []
    n_cited = 0
    for path, text in texts.items():
        for pos, name, section in cited_sections(text):
            if name not in cache:
                doc = ROOT / "docs" / name
                cache[name] = headings(doc) if doc.is_file() else None
            ids = cache[name]
            if ids is None:
                bad.append(f"{_where(path, text, pos)}  <- docs/{name} does not exist")
            elif section:
                n_cited += 1
                if section not in ids:
                    bad.append(f"{_where(path, text, pos)}  <- docs/{name} has no section {section}")
    assert not bad, "citations of docs/ that do not resolve:\n" + "\n".join(bad)
    assert n_cited > 100, f"only {n_cited} section citations of docs/ found: is the scan broken?"


#: The most lines docs/architecture.md may have (issue 47 item 5).
ARCHITECTURE_MAX_LINES = 500


def test_architecture_stays_a_description_of_today() -> None:
    text = (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")
    n_lines = len(text.splitlines())
    assert n_lines <= ARCHITECTURE_MAX_LINES, (
        f"docs/architecture.md has {n_lines} lines (at most {ARCHITECTURE_MAX_LINES}): describe today's design, "
        "move history to commit bodies")
    # the sections that code cites keep existing (test_every_cited_docs_section_exists checks each citation)
    assert {"1", "2", "3", "4", "5", "6", "7", "8", "8.1", "9", "10", "10.1", "11", "12"} <= headings(
        ROOT / "docs" / "architecture.md")


def test_papers_are_cited_by_key_only(texts: dict[Path, str]) -> None:
    """A paper is cited by its docs/references.md key ([Hindrax-Drag] eq. 1), never by a project-internal number."""
    refs = (ROOT / "docs" / "references.md").read_text(encoding="utf-8")
    for key in PAPER_KEYS:
        assert f"**{key}**" in refs, f"docs/references.md has no entry {key}"
    bad = [f"{_where(path, text, m.start())}  <- cite the paper by its docs/references.md key"
           for path, text in texts.items() for m in re.finditer(r"\b[Ss]eeds? 00[0-9]\b", text)]
    assert not bad, "papers cited by number instead of key:\n" + "\n".join(bad)


def test_the_scanner_finds_what_it_must() -> None:
    """The patterns above catch the forms they are meant for (so a passing scan means something)."""
    line = "see docs/devices.md §1.2-§1.5 and docs/devices.md §3.4-3.7, docs/architecture.md §6-7; " \
           "docs/identification.md §1.A, docs/devices.md §4.6b, docs/devices.md §2, §6 and §3.1."
    got = [(name, sec) for _, name, sec in cited_sections(line)]
    assert got == [("devices.md", "1.2"), ("devices.md", "1.5"), ("devices.md", "3.4"), ("devices.md", "3.7"),
                   ("architecture.md", "6"), ("architecture.md", "7"), ("identification.md", "1.A"),
                   ("devices.md", "4.6"), ("devices.md", "2"), ("devices.md", "6"), ("devices.md", "3.1")]
    outside = ["(" + OUTSIDE_NOTES[0] + " §1.3)", "../" + "shared/reference/x", "/" + "work/main/x",
               "/home/someone/notes.txt"]
    for sample in outside:
        assert any(p.search(sample) for p, _ in FORBIDDEN), sample
    for fine in ("docs/devices.md §1.3", "/dev/ttyUSB0", "/dev/i2c-1", "/opt/ros/jazzy", "/tmp/x"):
        assert not any(p.search(fine) for p, _ in FORBIDDEN), fine
