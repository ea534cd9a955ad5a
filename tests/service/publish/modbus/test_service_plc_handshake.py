"""The PLC handshake against a real pymodbus client on loopback: the result queue a slow PLC acknowledges
late, the command register and its answer, both heartbeats, and `moi modbus-map --read` as strict JSON."""

from __future__ import annotations

import json
import threading

import pytest
from pymodbus.client import ModbusTcpClient

from service.core.live import LiveStatus
from service.publish.modbus import registers as R
from service.publish.modbus.server import ModbusServer, ModbusSettings
from service.publish.replies import CommandReply
from tests.service.publish.modbus.test_service_modbus import synthetic

ILLEGAL_VALUE = 3
DEPTH = 4


class Clock:
    """A monotonic clock the test advances."""

    def __init__(self) -> None:
        self.t = 1000.0

    def __call__(self) -> float:
        return self.t


@pytest.fixture(scope="module")
def plc():
    """One ack-mode server and one client for the module; each test resets what it uses."""
    commands: list[tuple] = []
    got = threading.Event()

    def on_command(name, source, data=None, reply=None):
        commands.append((name, source, data, reply))
        got.set()

    clock = Clock()
    srv = ModbusServer(ModbusSettings(host="127.0.0.1", port=0, result_handshake="ack", queue_depth=DEPTH,
                                      plc_heartbeat_timeout=2.0),
                       on_command=on_command, recipe_numbers=frozenset({7}), clock=clock)
    srv.start()
    assert srv.bound_port is not None
    c = ModbusTcpClient("127.0.0.1", port=srv.bound_port, timeout=3, retries=0)
    assert c.connect()
    yield srv, c, commands, clock
    c.close()
    srv.stop()


def image(c) -> dict:
    rr = c.read_input_registers(0, count=R.IMAGE_SIZE, device_id=1)
    assert not rr.isError()
    return R.decode_image(rr.registers)


def bit(values: dict, name: str) -> bool:
    return bool(values["plc_status"] >> R.PLC_STATUS_BITS[name] & 1)


def write(c, name: str, *words: int):
    return c.write_registers(R.WRITABLE[name][0], list(words), device_id=1)


def test_a_slow_plc_loses_no_result_and_an_overrun_is_raised_only_past_the_depth(plc):
    srv, c, _, _ = plc
    for seq in range(1, DEPTH + 1):  # the PLC acknowledges none of them yet
        srv.publish_result(synthetic(seq))
    v = image(c)
    assert v["seq"] == v["seq_end"] == 1 and v["results_queued"] == DEPTH
    assert bit(v, "result_valid") and not bit(v, "result_buffer_overrun") and v["overrun_count"] == 0

    srv.publish_result(synthetic(DEPTH + 1))  # one past the depth: counted, flagged, not shown
    v = image(c)
    assert bit(v, "result_buffer_overrun") and v["overrun_count"] == 1 and v["results_queued"] == DEPTH
    assert v["error_code"] == R.ERROR_CODE_BY_NAME["result_buffer_overrun"] and bit(v, "error")

    # acknowledging anything but the shown seq is refused and changes nothing
    rr = write(c, "result_ack", 2)
    assert rr.isError() and rr.exception_code == ILLEGAL_VALUE
    assert image(c)["seq"] == 1 and image(c)["results_queued"] == DEPTH

    seen = []
    while bit(v := image(c), "result_valid"):
        seen.append(v["seq"])
        assert v["uuid"] == synthetic(v["seq"])["uuid"]  # the whole block is that result's
        assert not write(c, "result_ack", v["seq"]).isError()
    assert seen == list(range(1, DEPTH + 1))
    assert v["results_queued"] == 0 and v["seq"] == DEPTH  # the acknowledged values stay, not valid
    rr = write(c, "result_ack", DEPTH)  # nothing waits: refused
    assert rr.isError() and rr.exception_code == ILLEGAL_VALUE

    srv.publish_result(synthetic(DEPTH + 2))  # room again
    v = image(c)
    assert v["seq"] == DEPTH + 2 and bit(v, "result_valid") and v["overrun_count"] == 1
    assert not write(c, "result_ack", DEPTH + 2).isError()


def test_the_command_register_answers_and_refuses_bad_codes_with_illegal_value(plc):
    srv, c, commands, _ = plc
    commands.clear()
    for bad in ([99, 0], [4, 3]):  # an unknown command; select_recipe of an unknown recipe
        rr = write(c, "command", *bad)
        assert rr.isError() and rr.exception_code == ILLEGAL_VALUE
    assert commands == [] and image(c)["command_count"] == 0

    assert not write(c, "command", R.COMMAND_CODES["trigger"], 0).isError()
    (name, source, data, reply), = commands
    assert (name, source) == ("trigger", "modbus")
    count = image(c)["command_count"]
    reply(CommandReply("trigger", "accepted"))
    v = image(c)
    assert v["command_count"] == count + 1 and v["command_echo"] == 1
    assert v["command_status"] == R.COMMAND_STATUS["accepted"] and bit(v, "trigger_ack")
    assert not write(c, "command", 0).isError()  # the PLC takes its hand off
    assert not bit(image(c), "trigger_ack")

    reply(CommandReply("trigger", "done", data={"uuid": "x", "seq": 3}))
    assert image(c)["command_status"] == R.COMMAND_STATUS["done"]

    commands.clear()
    assert not write(c, "command", R.COMMAND_CODES["select_recipe"], 7).isError()
    (name, _, data, reply), = commands
    assert name == "recipe" and data == {"recipe": 7}
    reply(CommandReply("recipe", "refused", "busy"))
    v = image(c)
    assert v["command_status"] == R.COMMAND_STATUS["refused"]
    assert v["command_reason"] == CommandReply("recipe", "refused", "busy").reason_code == 1


def test_heartbeat_advances_with_the_main_loop_and_a_silent_plc_heartbeat_is_flagged(plc):
    srv, c, _, clock = plc
    srv.set_live(LiveStatus(state="IDLE"))
    first = image(c)["heartbeat"]
    clock.t += R.HEARTBEAT_PERIOD
    srv.set_live(LiveStatus(state="IDLE"))
    v = image(c)
    assert v["heartbeat"] == (first + 1) & 0xFFFF and bit(v, "ready")

    assert not write(c, "plc_heartbeat", 1).isError()
    clock.t += 1.5
    srv.set_live(LiveStatus(state="IDLE"))
    assert not bit(image(c), "plc_heartbeat_lost")
    clock.t += 1.0  # 2.5 s since the PLC's last change, timeout 2 s
    srv.set_live(LiveStatus(state="IDLE"))
    v = image(c)
    assert bit(v, "plc_heartbeat_lost") and v["error_code"] in (R.ERROR_CODE_BY_NAME["plc_heartbeat_lost"],)
    assert srv.health()["plc_heartbeat_lost"] and any("PLC heartbeat" in s for s in srv.status())
    assert not write(c, "plc_heartbeat", 1).isError()  # the same value is no sign of life
    srv.set_live(LiveStatus(state="IDLE"))
    assert bit(image(c), "plc_heartbeat_lost")
    assert not write(c, "plc_heartbeat", 2).isError()
    srv.set_live(LiveStatus(state="IDLE"))
    assert not bit(image(c), "plc_heartbeat_lost")


def test_status_word_says_calibration_due_and_not_decidable(plc):
    srv, c, _, _ = plc
    srv.set_live(LiveStatus(state="FAULT", fault=True, calibration_due=True))
    p = synthetic(40) | {"verdict": "NOK", "part": {"verdict": "NOK", "zone": "uncertainty"}}
    srv.publish_result(p)
    v = image(c)
    assert bit(v, "calibration_due") and bit(v, "error") and v["error_code"] == R.ERROR_CODE_BY_NAME["fault"]
    assert not bit(v, "ready")
    while bit(v, "result_valid") and not bit(v, "not_decidable"):  # results queued before it
        assert not write(c, "result_ack", v["seq"]).isError()
        v = image(c)
    assert v["seq"] == 40 and bit(v, "not_decidable")
    assert not write(c, "result_ack", 40).isError()
    srv.set_live(LiveStatus(state="IDLE"))


def test_modbus_map_read_prints_strict_json_with_raw_and_decoded_apart(plc, capsys):
    from service.cli import main

    srv, _, _, _ = plc
    srv.publish_result(synthetic(41) | {"J": None})  # J unknown: NaN in the registers
    assert main(["modbus-map", "--read", f"127.0.0.1:{srv.bound_port}"]) == 0

    def no_constants(name):
        raise AssertionError(f"{name} is not JSON")

    doc = json.loads(capsys.readouterr().out, parse_constant=no_constants)
    assert len(doc["raw"]) == R.IMAGE_SIZE and doc["decoded"]["J"] is None
    assert doc["raw"][str(R.BY_NAME["map_version"].address)] == R.MAP_VERSION
    assert isinstance(doc["decoded"]["plc_status"], list) and doc["decoded"]["error_code"] in (
        name for name, _ in R.ERROR_CODES.values())
    assert not srv.acknowledge(0)  # (the queue holds 41: only its seq acknowledges it)
    assert srv.acknowledge(41)


def test_the_daemon_answers_the_command_register_and_a_restart_queues_what_the_plc_did_not_acknowledge(
        tmp_path, appliance_factory):
    from tests.service.conftest import appliance_doc, wait_until

    doc = appliance_doc(tmp_path / "state", modbus={"result_handshake": "ack", "queue_depth": DEPTH})
    app = appliance_factory(doc)
    c = ModbusTcpClient("127.0.0.1", port=app.app.modbus.bound_port, timeout=3, retries=0)
    assert c.connect()
    try:
        for n in (1, 2):
            count = image(c)["command_count"]
            assert not write(c, "command", R.COMMAND_CODES["trigger"], 0).isError()
            v = wait_until(lambda: (v := image(c))["command_count"] >= count + 2 and v, 30, what="trigger done")
            assert v["command_echo"] == 1 and v["command_status"] == R.COMMAND_STATUS["done"]
            assert not write(c, "command", 0).isError()
            app.wait_done(n)
        v = image(c)
        assert v["results_queued"] == 2 and bit(v, "result_valid")
        first = v["seq"]
        assert not write(c, "result_ack", first).isError()
        second = image(c)["seq"]
        assert second > first
        # the abort command with nothing to abort: refused, with its reason
        count = image(c)["command_count"]
        assert not write(c, "command", R.COMMAND_CODES["abort"], 0).isError()
        v = wait_until(lambda: (v := image(c))["command_count"] > count and v, 10, what="abort answered")
        assert v["command_status"] == R.COMMAND_STATUS["refused"]
        assert v["command_reason"] == CommandReply("abort", "refused", "nothing_to_abort").reason_code
    finally:
        c.close()
    assert app.stop() == 0

    again = appliance_factory(doc)  # the same state directory: the unacknowledged result is queued again
    c = ModbusTcpClient("127.0.0.1", port=again.app.modbus.bound_port, timeout=3, retries=0)
    assert c.connect()
    try:
        v = image(c)
        assert v["seq"] == second and v["results_queued"] == 1 and bit(v, "result_valid")
        assert not write(c, "result_ack", second).isError()
        assert not bit(image(c), "result_valid")
    finally:
        c.close()
