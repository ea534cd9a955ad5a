"""The gates only tighten: the functions allowed over ruff's complexity limit, and the product modules and
functions allowed over the size limits, are lists that may only shrink.

ruff's McCabe check (C901, ``max-complexity`` in pyproject.toml) fails a function over the limit unless its
``def`` line ends in a noqa comment for C901. Those that did when the limit came in are listed here: a new
one fails this test, and so does a listed one that no longer carries it (simplified: delete its line here).
ruff's RUF100 says when a listed function has become simple enough for its noqa to go.

The size limits: a product module holds one concern (at most ``MODULE_LINES`` lines), a function fits on a
screen (at most ``FUNCTION_LINES`` lines from its ``def`` to its last line). The ones over them are listed:
a new one fails, and so does a listed one that is no longer over (delete its line).
"""

from __future__ import annotations

import ast
import re
import tomllib
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
#: where the tree's Python lives (what `ruff check .` reads, less the virtual environment)
ROOTS = ("measurement", "drivers", "firmware_host", "service", "tests", "bench", "docs", "examples")
LIMIT = 15

#: file → the functions over the limit that may stay so for now. Only ever delete from this list.
ALLOWED_OVER_LIMIT: dict[str, set[str]] = {}

#: the product code the size limits hold for (tests, benches and examples are not product)
PRODUCT = ("measurement", "drivers", "firmware_host", "service")
MODULE_LINES = 600
FUNCTION_LINES = 80

#: the product modules over MODULE_LINES that may stay so for now. Only ever delete from this list.
ALLOWED_LONG_MODULES: set[str] = set()

#: file → the product functions over FUNCTION_LINES that may stay so for now. Only ever delete from this list.
ALLOWED_LONG_FUNCTIONS: dict[str, set[str]] = {}

_DEF = re.compile(r"^\s*(?:async\s+)?def\s+(\w+)")
_NOQA_C901 = re.compile(r"#\s*noqa:[^#]*\bC90(?:1)?\b", re.IGNORECASE)
_FILE_NOQA = re.compile(r"#\s*ruff\s*:\s*noqa(?!\s*:)|#\s*ruff\s*:\s*noqa:[^#]*\bC90", re.IGNORECASE)


def _sources():
    for root in ROOTS:
        yield from sorted((REPO / root).rglob("*.py"))


def test_the_functions_over_the_complexity_limit_are_the_listed_ones():
    found: dict[str, set[str]] = {}
    for path in _sources():
        rel = path.relative_to(REPO).as_posix()
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            assert not _FILE_NOQA.search(line), f"{rel}:{number}: a file-wide noqa would hide every complex function"
            if _NOQA_C901.search(line):
                name = _DEF.match(line)
                assert name, f"{rel}:{number}: `noqa: C901` belongs on the def line of the function it excuses"
                found.setdefault(rel, set()).add(name.group(1))
    new = {f: names - ALLOWED_OVER_LIMIT.get(f, set()) for f, names in found.items()}
    new = {f: n for f, n in new.items() if n}
    assert not new, (f"functions newly excused from the complexity limit of {LIMIT}: {new}; split them into "
                     "functions under it rather than adding a `noqa: C901`")
    gone = {f: names - found.get(f, set()) for f, names in ALLOWED_OVER_LIMIT.items()}
    gone = {f: n for f, n in gone.items() if n}
    assert not gone, f"no longer excused (simplified, renamed or moved): {gone}; delete them from ALLOWED_OVER_LIMIT"


def test_the_limit_and_the_rule_stay_on_for_every_file():
    lint = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["ruff"]["lint"]
    assert lint["mccabe"]["max-complexity"] == LIMIT
    assert "C90" in lint["select"] and not {"C90", "C901"} & set(lint.get("ignore", []))
    excused = {f: codes for f, codes in lint.get("per-file-ignores", {}).items() if {"C90", "C901"} & set(codes)}
    assert not excused, f"per-file exceptions to the complexity limit: {excused}; list functions instead"


def _product_sources():
    for root in PRODUCT:
        for path in sorted((REPO / root).rglob("*.py")):
            yield path.relative_to(REPO).as_posix(), path.read_text(encoding="utf-8")


def test_the_product_modules_over_the_size_limit_are_the_listed_ones():
    found = {rel for rel, text in _product_sources() if len(text.splitlines()) > MODULE_LINES}
    new = found - ALLOWED_LONG_MODULES
    assert not new, (f"modules over {MODULE_LINES} lines: {sorted(new)}; split them by concern, one module each, "
                     "named for it")
    gone = ALLOWED_LONG_MODULES - found
    assert not gone, f"no longer over {MODULE_LINES} lines (or gone): {sorted(gone)}; delete them from ALLOWED_LONG_MODULES"


def test_the_product_functions_over_the_size_limit_are_the_listed_ones():
    found: dict[str, set[str]] = {}
    for rel, text in _product_sources():
        for node in ast.walk(ast.parse(text, filename=rel)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and node.end_lineno is not None \
                    and node.end_lineno - node.lineno + 1 > FUNCTION_LINES:
                found.setdefault(rel, set()).add(node.name)
    new = {f: names - ALLOWED_LONG_FUNCTIONS.get(f, set()) for f, names in found.items()}
    new = {f: n for f, n in new.items() if n}
    assert not new, (f"functions over {FUNCTION_LINES} lines: {new}; split them into named steps "
                     "(aim at 60 lines at most)")
    gone = {f: names - found.get(f, set()) for f, names in ALLOWED_LONG_FUNCTIONS.items()}
    gone = {f: n for f, n in gone.items() if n}
    assert not gone, (f"no longer over {FUNCTION_LINES} lines (split, renamed or moved): {gone}; delete them from "
                      "ALLOWED_LONG_FUNCTIONS")
