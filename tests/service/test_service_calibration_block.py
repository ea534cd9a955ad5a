"""Measure refused at every door while the calibration blocks it: the push button (its status lamp), a Modbus
coil and the command register (reason 12, `ready` clear), MQTT (the reply's reason and words), against the
daemon on the simulated rig with real peers on loopback; a check standard still measured when its passing is
what clears the block, and not when the calibration itself expired."""

from __future__ import annotations

import datetime as dt
import logging
import time

from pymodbus.client import ModbusTcpClient

from service.publish.modbus import registers as R
from service.publish.replies import REASONS
from tests.service.conftest import appliance_doc, wait_until
from tests.service.publish.modbus.test_service_plc_handshake import bit, image, write
from tests.service.publish.mqtt.test_service_mqtt_replies import V5Client

BASE = "moi/test-rig"
EXPIRED = "calibration expired on 2021-01-14: recalibrate (moi calibrate) or call the quality engineer on shift"


def _rigs(tmp_path):
    """The device's rig calibrated last month (valid), a recipe rig whose calibration expired on 2021-01-14, and
    recipes: a part on each rig, the check standard on each rig."""
    fresh = (dt.date.today() - dt.timedelta(days=30)).isoformat()
    for name, date in (("fresh", fresh), ("old", "2020-01-15")):
        (tmp_path / f"{name}-rig.toml").write_text(f'[rig]\nkind = "torsion"\nstiffness = 0.3651\n[calibration]\n'
                                                   f'date = {date}\nvalid_days = 365\n')
    recipes = tmp_path / "recipes"
    recipes.mkdir()
    cs = '[check_standard]\nname = "disc CS-1"\nreference = 0.0125\nreference_U = 2.0e-5\n'
    for n, (name, rig, extra) in enumerate((("rotor", "fresh", ""), ("rotor-old", "old", ""),
                                            ("cs", "fresh", cs), ("cs-old", "old", cs)), start=1):
        (recipes / f"{name}.toml").write_text(f'[recipe]\nname = "{name}"\nnumber = {n}\nnominal = 0.0125\n'
                                              f'tolerance_percent = 2.0\nrig = "../{rig}-rig.toml"\n{extra}')
    return tmp_path / "fresh-rig.toml", recipes


def _when(c, name: str) -> dict:
    """The registers once the status bit ``name`` is set (the live status reaches them on the next loop)."""
    return wait_until(lambda: (v := image(c)) and bit(v, name) and v, 10, what=name)


def _devices(doc):
    """The simulated rig's devices with a status lamp on a mock pin (the simulated rig has none of its own)."""
    from drivers.backend import pin_factory
    from drivers.indicator import Indicator
    from service.config.appliance import parse_config
    from service.devices.hardware import build_devices

    devices = build_devices(parse_config(doc, source="test.toml"))
    shown: list[str] = []

    class Recorded(Indicator):  # the real driver, each state it is told to show recorded
        def show(self, state: str) -> None:
            shown.append(state)
            super().show(state)

    devices.indicator = Recorded(22, kind="led", pin_factory=pin_factory("mock"))
    return devices, shown


def test_every_door_refuses_measure_while_the_calibration_expired(tmp_path, broker, appliance_factory, caplog):
    rig, recipes = _rigs(tmp_path)
    doc = appliance_doc(tmp_path / "state", mqtt_port=broker.port, device={"rig": str(rig)},
                        recipes={"directory": str(recipes), "active": "rotor-old"})
    devices, shown = _devices(doc)
    running = appliance_factory(doc, devices=devices)
    app = running.app
    assert app.mqtt.subscribed_event.wait(10)
    c = ModbusTcpClient("127.0.0.1", port=app.modbus.bound_port, timeout=3, retries=0)
    assert c.connect()
    mine = f"{BASE}/reply/plant-mes"
    m = V5Client(broker.port, [mine])
    caplog.set_level(logging.WARNING, logger="moi.daemon")
    try:
        # the PLC sees it before it tries: not ready, calibration due; the lamp shows it, not "ready"
        v = _when(c, "calibration_due")
        assert not bit(v, "ready") and v["state"] == R.STATE_CODES["IDLE"]
        wait_until(lambda: devices.indicator.shown == "BLOCKED", 10, what="the lamp's BLOCKED")

        # the command register: refused with reason 12
        count = v["command_count"]
        assert not write(c, "command", R.COMMAND_CODES["trigger"], 0).isError()
        v = wait_until(lambda: (v := image(c))["command_count"] > count and v, 10, what="trigger answered")
        assert v["command_status"] == R.COMMAND_STATUS["refused"]
        assert v["command_reason"] == REASONS["calibration_due"].code == 12 and not bit(v, "trigger_ack")
        assert not write(c, "command", 0).isError()

        # MQTT: the reply says why, what to do and whom to call
        m.send("measure", {"id": "m1"}, response_topic=mine, correlation=b"c")
        r = m.wait_for(lambda g: g[1]["id"] == "m1")[1]
        assert (r["status"], r["reason"]) == ("refused", "calibration_due") and r["detail"] == EXPIRED

        # the coil and the push button: nothing starts; the lamp shows the refusal again at the press
        before = len(shown)
        assert not c.write_coil(R.COILS["trigger"], True, device_id=1).isError()
        running.press()
        wait_until(lambda: shown[before:].count("BLOCKED") >= 2, 10, what="both presses refused on the lamp")
        refused = [r.getMessage() for r in caplog.records if "refused" in r.getMessage()]
        assert refused and EXPIRED in refused[0]  # said once in the log (a stuck button does not flood it)

        # a check standard on the expired rig: refused too (a check does not renew a calibration)
        m.send("measure", {"id": "m2", "recipe": "cs-old"}, response_topic=mine, correlation=b"c")
        r = m.wait_for(lambda g: g[1]["id"] == "m2")[1]
        assert (r["status"], r["reason"]) == ("refused", "calibration_due")
        assert app.store.count() == 0 and app.sequencer.counts["measurements"] == 0

        # the rig of a calibrated recipe: ready again, the lamp back to steady, and the button measures
        m.send("recipe", {"id": "r1", "recipe": "rotor"}, response_topic=mine, correlation=b"c")
        assert m.wait_for(lambda g: g[1]["id"] == "r1")[1]["status"] == "done"
        v = _when(c, "ready")
        assert not bit(v, "calibration_due") and devices.indicator.shown == "IDLE"
        running.press()
        running.wait_done(1)
        assert app.store.latest().payload["trigger"] == "button"
    finally:
        m.close()
        c.close()


def test_a_failed_check_standard_refuses_parts_but_not_the_check_standard_that_clears_it(
        tmp_path, broker, appliance_factory):
    rig, recipes = _rigs(tmp_path)
    doc = appliance_doc(tmp_path / "state", mqtt_port=broker.port, device={"rig": str(rig)},
                        recipes={"directory": str(recipes), "active": "rotor"}, web={"contact": "the lab, ext. 2345"})
    doc["web"]["enabled"] = True
    running = appliance_factory(doc)
    app = running.app
    assert app.mqtt.subscribed_event.wait(10)
    app.store.record_check_standard({"name": "disc CS-1", "quantity": "J", "value": 0.01262, "U": 2e-5,
                                     "reference": 0.0125, "reference_U": 2e-5, "E_n": 4.29, "passed": False},
                                    finished_at=time.time())
    mine = f"{BASE}/reply/plant-mes"
    m = V5Client(broker.port, [mine])
    try:
        m.send("measure", {"id": "m1"}, response_topic=mine, correlation=b"c")
        r = m.wait_for(lambda g: g[1]["id"] == "m1")[1]
        assert (r["status"], r["reason"]) == ("refused", "calibration_due")
        assert r["detail"] == ("check standard disc CS-1 failed (E_n = 4.29): find the cause and measure the check "
                               "standard again or call the lab, ext. 2345")
        # the check standard itself is measured: its passing is what clears the block
        m.send("measure", {"id": "m2", "recipe": "cs"}, response_topic=mine, correlation=b"c")
        assert m.wait_for(lambda g: g[1]["id"] == "m2")[1]["status"] == "accepted"
        running.wait_done(1)
    finally:
        m.close()
