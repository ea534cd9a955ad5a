"""The calibration rule: whether the rig a part is measured with is calibrated, and whether that refuses a
measurement. Pure: the rig, the newest check standard, the recipe and the time in; a state or a block out.

The rig's calibration is due past its validity period, and also while the newest check standard (`moi
check-standard`, or a check-standard recipe measured at the station) measured since the calibration failed
(E_n > 1): the budget no longer covers what the rig does. Every result is then flagged ``calibration_due``.
A trigger is refused (``measure_block``) when every result of the active recipe would be INVALID for it, so
that measuring again cannot change the verdict; the daemon and every door (button, Modbus, MQTT, Sparkplug,
web) ask the same rule and say the same words (``calibration_words``).

A rig without a calibration record is not blocked (a demo rig, or one set up by hand, has its k from the rig
file) but never passes in silence either: every door that shows the calibration says ``UNCALIBRATED``
(``uncalibrated``), of the rig now and of each result measured so; ``[device] require_calibration`` makes it a
block like an expired calibration.
"""

from __future__ import annotations

import datetime as dt
from typing import TYPE_CHECKING, Any, Mapping, Sequence

from measurement import Rig

if TYPE_CHECKING:  # pragma: no cover
    from service.parts.recipes import Recipe


#: what every door says of a rig that has no calibration record (its k is the rig file's, checked by nobody)
UNCALIBRATED = "rig not calibrated: k from the rig file, no calibration record"


def uncalibrated(state: Mapping[str, Any] | None) -> str | None:
    """``UNCALIBRATED`` when a calibration state (``calibration_state``, now or as a result stored it) has no
    calibration record behind it: None (no record, no failed check) or a state without a calibration date (no
    record, a failed check standard: blocked besides); None when the rig is calibrated."""
    return UNCALIBRATED if state is None or state.get("date") is None else None


def _today(now: float) -> dt.date:
    return dt.datetime.fromtimestamp(now, dt.UTC).date()


def calibration_state(rig: Rig, checks: Sequence[Mapping[str, Any]], now: float) -> dict[str, Any] | None:
    """The rig's calibration as of ``now`` (Unix s): date, valid_until, whether it is due, the stiffness it gives
    and the newest check standard since it (``checks``: the stored check standards, newest first); None when the
    rig has no calibration record and no check standard failed."""
    cal = rig.calibration
    check = checks[0] if checks else None
    if check is not None and cal is not None:
        calibrated = dt.datetime.combine(cal.date, dt.time(), dt.UTC).timestamp()
        if check["finished_at"] < calibrated:
            check = None  # a check before the calibration says nothing about it
    failed = check is not None and not check["passed"]
    if cal is None and not failed:
        return None
    until = cal.valid_until if cal is not None else None
    state: dict[str, Any] = {
        "date": cal.date.isoformat() if cal is not None else None,
        "valid_until": until.isoformat() if until else None,
        "due": (cal is not None and cal.due(_today(now))) or failed, "stiffness": rig.stiffness,
        "stiffness_std": rig.stiffness_std}
    if check is not None:
        state["check_standard"] = {k: check.get(k) for k in ("name", "E_n", "passed", "finished_at")}
    return state


def measure_block(rig: Rig, recipe: Recipe | None, checks: Sequence[Mapping[str, Any]], now: float,
                  contact: str, require_record: bool = False) -> dict[str, Any] | None:
    """Why no measurement of ``recipe`` (None: no recipe is active) on ``rig`` may start at ``now``, or None.

    The calibration is due (``calibration_state``): every result would carry calibration_due and be INVALID. A
    check-standard recipe is still measured while only a failed check standard blocks, since its passing is what
    clears the block; an expired calibration refuses it too (a check cannot renew a calibration: ``moi
    calibrate`` does). A recipe whose ``invalid_flags`` leave out ``calibration_due`` is measured too: its parts
    are judged, flagged. A rig without a calibration record (``uncalibrated``) is refused only when
    ``require_record`` (``[device] require_calibration``) asks. Returns the calibration state, ``expired``,
    ``uncalibrated`` and ``detail``: the words every door says, with whom to call (``contact``)."""
    state = calibration_state(rig, checks, now)
    if require_record and rig.calibration is None:
        return {"calibration": state or {}, "expired": False, "uncalibrated": True,
                "detail": f"{UNCALIBRATED}: calibrate the rig (moi calibrate) or call {contact}"}
    if not state or not state["due"]:
        return None
    cal = rig.calibration
    expired = cal is not None and cal.due(_today(now))
    if not expired and recipe is not None and recipe.check_standard is not None:
        return None
    if (recipe is not None and recipe.check_standard is None
            and "calibration_due" not in recipe.quality.invalid_flags):
        return None  # its quality rules judge a part with the calibration due (flagged, not INVALID): its call
    check = state.get("check_standard")
    failed = check if check is not None and not check.get("passed") else None
    return {"calibration": state, "expired": expired, "uncalibrated": False,
            "detail": calibration_words(state["valid_until"] if expired else None, failed, contact)}


def calibration_words(expired_on: str | None, check: Mapping[str, Any] | None, contact: str) -> str:
    """What every door says when the calibration refuses a measurement (``measure_block``): the calibration
    expired on ``expired_on`` (YYYY-MM-DD; None: it did not), and/or the check standard ``check`` (name, E_n)
    failed; what to do, and whom to call."""
    what, do = [], []
    if expired_on is not None:
        what.append(f"calibration expired on {expired_on}")
        do.append("recalibrate (moi calibrate)")
    if check is not None:
        e_n = check.get("E_n")
        what.append(f"check standard {check.get('name') or ''} failed"
                    + (f" (E_n = {e_n:.2f})" if isinstance(e_n, (int, float)) else ""))
        if expired_on is None:
            do.append("find the cause and measure the check standard again")
    return f"{' and '.join(what)}: {' and '.join(do)} or call {contact}"
