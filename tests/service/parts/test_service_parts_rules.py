"""The part's rules as pure functions: the calibration rule (rig, check standards, recipe → a state and a block),
the [recipe] keys declared once (what the loader, the editor and the page read)."""

from __future__ import annotations

import dataclasses
import datetime as dt
from types import SimpleNamespace

import pytest

from measurement.rig import CalibrationRecord
from service.parts.calibration import calibration_state, measure_block
from service.parts.recipe_keys import EDITABLE, RECIPE_KEYS, schema
from service.settings.defaults import DEMO_RIG

NOW = dt.datetime(2026, 6, 1, 12, tzinfo=dt.UTC).timestamp()


def rig(calibrated: dt.date, valid_days: int):
    return dataclasses.replace(DEMO_RIG, calibration=CalibrationRecord(calibrated, valid_days))


def recipe(check_standard: bool = False, invalid_flags: tuple[str, ...] = ("calibration_due",)):
    return SimpleNamespace(check_standard={"name": "CS"} if check_standard else None,
                           quality=SimpleNamespace(invalid_flags=invalid_flags))


def test_the_calibration_rule_blocks_only_what_measuring_again_cannot_change():
    valid, expired = rig(dt.date(2026, 5, 1), 365), rig(dt.date(2025, 1, 1), 30)
    failed = [{"name": "CS", "E_n": 1.8, "passed": False, "finished_at": NOW - 60}]
    def due(r, checks):
        state = calibration_state(r, checks, NOW)
        assert state is not None
        return state["due"]

    assert calibration_state(DEMO_RIG, [], NOW) is None  # no record, no failed check: nothing to say
    assert due(valid, []) is False
    assert due(valid, failed) is True
    # a check older than the calibration says nothing about it
    old = [dict(failed[0], finished_at=dt.datetime(2026, 4, 1, tzinfo=dt.UTC).timestamp())]
    assert due(valid, old) is False
    assert measure_block(valid, recipe(), [], NOW, "QA") is None
    block = measure_block(valid, recipe(), failed, NOW, "QA")
    assert block is not None and not block["expired"] and "check standard CS failed (E_n = 1.80)" in block["detail"]
    assert block["detail"].endswith("or call QA")
    # the check standard itself is measured (its passing clears the block), unless the calibration expired
    assert measure_block(valid, recipe(check_standard=True), failed, NOW, "QA") is None
    cs_expired = measure_block(expired, recipe(check_standard=True), [], NOW, "QA")
    assert cs_expired is not None and cs_expired["expired"] and "recalibrate" in cs_expired["detail"]
    # a recipe whose quality rules judge a due calibration (flagged, not INVALID) is measured
    assert measure_block(expired, recipe(invalid_flags=()), [], NOW, "QA") is None


def test_each_recipe_key_is_declared_once_for_the_loader_the_editor_and_the_page():
    assert list(schema()) == [k.name for k in RECIPE_KEYS]
    assert [k.label for k in EDITABLE] == ["nominal (kg·m²)", "tolerance (kg·m²)", "tolerance percent (± %)",
                                           "releases", "display unit", "display decimals"]
    keys = {k.name: k for k in EDITABLE}
    assert [k.name for k in EDITABLE if k.either] == ["tolerance", "tolerance_percent"]
    assert keys["releases"].inputmode == "numeric" and keys["nominal"].inputmode == "text"
    assert keys["releases"].parse(" 3 ") == 3 and keys["nominal"].parse("") is None
    with pytest.raises(ValueError, match="whole number"):
        keys["releases"].parse("2.5")
    with pytest.raises(ValueError, match="finite"):
        keys["nominal"].parse("nan")
    assert keys["nominal"].typed(1.25e-05) == "0.0000125" and keys["releases"].typed(None) is None
