"""The README says what the code does: its effect table and the Modbus snapshot's register range."""

from __future__ import annotations

import re
from pathlib import Path

from measurement.effects import EFFECTS
from service.publish.modbus import registers as R

README = (Path(__file__).resolve().parents[1] / "README.md").read_text(encoding="utf-8")


def effect_rows() -> dict[str, tuple[str, str]]:
    """name → (torque term, typical cause) of the README's effect table (Markdown's \\| unescaped)."""
    rows = {}
    for line in README.splitlines():
        cells = [c.strip().replace("\\|", "|") for c in re.split(r"(?<!\\)\|", line)[1:-1]]
        if len(cells) == 3 and re.fullmatch(r"`\w+`", cells[0]):
            rows[cells[0].strip("`")] = (cells[1], cells[2])
    return rows


def test_the_effect_table_lists_every_effect_of_the_library_once():
    assert sorted(effect_rows()) == sorted(EFFECTS)


def test_each_row_gives_the_effects_law_and_cause():
    rows = effect_rows()
    for name, cls in EFFECTS.items():
        term, cause = rows[name]
        law = re.sub(r" \([^()]*\)$", "", cls.law)  # the README explains the closing remark in its own words
        assert law in term, (name, law, term)
        assert cause == cls.cause, (name, cause, cls.cause)


def test_the_snapshot_register_range_is_the_maps():
    first, last = R.SNAPSHOT_START, R.SNAPSHOT_END - 1
    ranges = set(re.findall(r"(?:registers|block) (\d+)–(\d+) \(|block (\d+)–(\d+) in one request", README))
    said = {(int(a or c), int(b or d)) for a, b, c, d in ranges}
    assert said == {(first, last)}, f"the README gives {said}; the map's snapshot is {first}–{last}"
