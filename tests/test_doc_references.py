"""Every `tests/<path>.py` that the README, the docs or the package's docstrings and comments name
exists: the tests moved into subfolders (tests/model, tests/surrogate, ...) once and 34 references
went stale. CHANGELOG.md is history (it names files as they were then) and is not read."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
REFERENCE = re.compile(r"\btests/[A-Za-z0-9_/.-]*?\.py\b")


def _sources() -> list[Path]:
    docs = [p for p in (ROOT / "docs").rglob("*.md") if "design" not in p.relative_to(ROOT / "docs").parts[:1]]
    code = [p for p in (ROOT / "persival").rglob("*.py") if "node_modules" not in p.parts]
    return [ROOT / "README.md", *sorted(docs), *sorted(code)]


def _references(path: Path) -> list[tuple[int, str]]:
    return [(number, match) for number, line in enumerate(path.read_text(errors="replace").splitlines(), 1)
            for match in REFERENCE.findall(line)]


def test_the_pattern_finds_references():
    # a reference to a file that is there, and one with a test's name after it
    assert REFERENCE.findall("see tests/evaluate/test_report.py::test_x and `tests/conftest.py`") == [
        "tests/evaluate/test_report.py", "tests/conftest.py"]


def test_every_named_test_file_exists():
    missing = [f"{path.relative_to(ROOT)}:{number}: {reference}" for path in _sources()
               for number, reference in _references(path) if not (ROOT / reference).is_file()]
    assert not missing, "references to test files that do not exist (moved?):\n" + "\n".join(missing)
