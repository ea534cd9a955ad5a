"""docs/architecture.md stays the map of the code: what it names exists, and every room is on it.

A name in backticks that ends in ``.py`` or ``/`` is a module or a room; it must exist, spelled from the
repository's root or as the tail of a path (``focus.py`` inside the identification's table,
``sparkplug/`` inside the publishers' row). A template (``<name>.py``) names no file. Every package
directory of the four packages (a room) and every top-level directory of the repository is named. The page
says what is, not what was: history belongs in the CHANGELOG, so no table keeps a "before" column.
"""

from __future__ import annotations

import re
import subprocess
from functools import cache
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PAGE = REPO / "docs" / "architecture.md"
PACKAGES = ("measurement", "drivers", "firmware_host", "service")
_TICKED = re.compile(r"`([^`\s<>]+(?:\.py|/))`")


def _text() -> str:
    return PAGE.read_text(encoding="utf-8")


@cache
def _tracked() -> frozenset[str]:
    """The repository's files and directories, as posix paths from its root (what a clone has)."""
    files = subprocess.run(["git", "ls-files"], cwd=REPO, capture_output=True, text=True, check=True).stdout.split()
    paths = set(files)
    for f in files:
        parts = f.split("/")
        paths.update("/".join(parts[:i]) + "/" for i in range(1, len(parts)))
    return frozenset(paths)


def _exists(name: str) -> bool:
    return any(p == name or p.endswith("/" + name) for p in _tracked())


def _rooms() -> list[str]:
    return sorted(p.parent.relative_to(REPO).as_posix() + "/"
                  for pkg in PACKAGES for p in (REPO / pkg).rglob("__init__.py")
                  if "__pycache__" not in p.parts)


def test_every_module_and_room_the_page_names_exists():
    named = set(_TICKED.findall(_text()))
    assert named, "the page names no module: the pattern no longer reads it"
    missing = sorted(n for n in named if not _exists(n))
    assert not missing, f"docs/architecture.md names modules or rooms that are not in the tree: {missing}"


def test_every_room_and_top_level_directory_is_on_the_page():
    named = set(_TICKED.findall(_text()))
    top = sorted(p for p in _tracked() if p.endswith("/") and p.count("/") == 1)
    absent = [room for room in _rooms() + top
              if not any(room == n or room.endswith("/" + n) for n in named if n.endswith("/"))]
    assert not absent, f"rooms or directories missing from docs/architecture.md: {absent}"


def test_the_page_keeps_no_history():
    headers = [line for line in _text().splitlines() if re.match(r"\|.*\|\s*before\s*\|", line, re.IGNORECASE)]
    assert not headers, f"tables with a 'before' column (history belongs in the CHANGELOG): {headers}"
