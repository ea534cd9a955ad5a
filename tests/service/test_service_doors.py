"""The doors added since the last attack pass (OPC UA, MQTT replies, hostile names) must not let anyone stop a
measurement or lose one: attacks on the running daemon (simulated rig, loopback only, bounded in count)."""

from __future__ import annotations

import pytest

from .conftest import appliance_doc, wait_until


# --- a measurement once captured is always stored ---------------------------------------------------------------

def test_a_failure_while_the_part_is_judged_still_stores_the_measurement_with_its_trace(tmp_path, appliance_factory):
    """The swing was captured and identified, then judging it raised: a failed row holds the trace and the
    failure, and the appliance goes to FAULT (what the PLC and MQTT see)."""
    app = appliance_factory(appliance_doc(tmp_path / "state"))

    def broken(*args, **kwargs):
        raise RuntimeError("judging broke")

    app.app.parts.release = broken
    app.press()
    app.wait_event(lambda e: e.state.value == "FAULT", 60, what="FAULT after judging failed")
    wait_until(lambda: app.app.stored, 10, what="the failed row")
    rows = app.app.store.list(limit=None, full=True)
    assert [r.status for r in rows] == ["failed"]
    assert "judging broke" in (rows[0].error or "")
    stored = app.app.store.get(rows[0].uuid, trace=True)
    assert stored.trace_angle is not None and len(stored.trace_angle) > 100
