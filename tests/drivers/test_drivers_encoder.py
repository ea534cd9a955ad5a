"""The Modbus RTU encoder client against the simulated encoder: a real pymodbus RTU server on loopback."""

import math

import numpy as np
import pytest

from drivers.clock import ScaledClock
from drivers.encoder import EncoderConfig, ModbusEncoder, bad_crc
from drivers.errors import DriverConfigError, EncoderFault
from drivers.sim_encoder import SimEncoderConfig, SimEncoderServer, free_tcp_port
from measurement.errors import InvalidInput

OMEGA = 2 * math.pi * 2.0  # rad/s: a 2 Hz test motion
AMPLITUDE = 0.3            # rad


def wave(t):
    return AMPLITUDE * math.sin(OMEGA * t)


@pytest.fixture
def clock():
    return ScaledClock(1.0)


def capture(encoder, n, timeout=20.0):
    encoder.start()
    reached = encoder.wait_for_samples(n, timeout)
    encoder.stop()
    t, a = encoder.read()
    return reached, t, a


def test_samples_arrive_in_order_with_midpoint_timestamps(clock):
    with SimEncoderServer(wave, clock, SimEncoderConfig(latency=0.0005)) as server, \
            ModbusEncoder(server.encoder_config(), clock) as enc:
        t_start = clock.now()
        reached, t, a = capture(enc, 300)
        t_end = clock.now()
        assert reached and len(t) >= 300
        assert np.all(np.diff(t) > 0)
        assert t_start < t[0] and t[-1] < t_end
        # each sample is the true angle at its timestamp, within what the round trip and the
        # 17-bit quantisation allow (the server latches between request and reply)
        rtt = enc.stats()["rtt_max_s"]
        truth = np.array([wave(x) for x in t])
        bound = OMEGA * AMPLITUDE * rtt / 2 + 2 * math.pi / 2**17
        assert np.max(np.abs(a - truth)) <= bound
        s = enc.stats()
        # a clean bus corrupts nothing; a busy host may let a reply miss its time-out now and then
        assert s["samples"] == len(t) and s["crc_errors"] == 0 and s["errors"] == s["timeouts"] and s["rate_hz"] > 0


def test_dropped_and_corrupted_replies_are_counted_by_kind(clock):
    cfg = SimEncoderConfig(drop_rate=0.15, crc_error_rate=0.1, seed=7)
    with SimEncoderServer(wave, clock, cfg) as server, \
            ModbusEncoder(server.encoder_config(timeout=0.01, max_consecutive_errors=50), clock) as enc:
        reached, t, a = capture(enc, 250)
        assert reached
        s, wire = enc.stats(), dict(server.counts)
    # the request in flight at stop() may be counted on one side only; every dropped reply is a time-out; a
    # reply a busy host let arrive after its 10 ms time-out is a time-out too, counted as stale if it comes
    # before the next request's reply, else discarded with the line's leftovers
    stale = s["stale_replies"]
    assert s["timeouts"] - stale >= wire["dropped"] - 1 and s["timeouts"] > 0
    assert wire["corrupted"] - stale - 1 <= s["crc_errors"] <= wire["corrupted"] + 1 and s["crc_errors"] > 0
    assert s["errors"] == s["timeouts"] + s["crc_errors"]
    assert s["samples"] == len(t)
    assert enc.flags() == ("encoder_errors",)
    assert np.all(np.diff(t) > 0)
    truth = np.array([wave(x) for x in t])
    assert np.max(np.abs(a - truth)) < OMEGA * AMPLITUDE * s["rtt_max_s"]  # no corrupted value slipped through


def test_a_reply_after_its_time_out_is_never_taken_for_the_next_requests_answer(clock):
    # RTU carries no transaction id: a reply late for its time-out, arriving while the next request was in
    # flight, was once taken for its answer (an angle one request old). The reply comes 50 ms after the
    # 100 ms time-out and 50 ms before the quiet wait after it ends: a host that wakes its reader tens of
    # milliseconds late (a loaded machine) still sees it late, and still within the wait
    with SimEncoderServer(wave, clock, SimEncoderConfig(latency=0.15)) as server, \
            ModbusEncoder(server.encoder_config(timeout=0.1, max_consecutive_errors=20), clock) as enc:
        enc.start()
        assert not enc.wait_for_samples(1, 20.0)  # woken by the fault: no late reply passed for a sample
        with pytest.raises(EncoderFault, match=r"20 failed reads in a row.*no reply within 0.1 s"):
            enc.read()
        s = enc.stats()
    assert s["samples"] == 0 and s["timeouts"] == 20
    assert s["stale_replies"] >= 19  # each late reply came in the quiet wait after its time-out


def test_illegal_address_replies_are_counted_then_fault(clock):
    with SimEncoderServer(wave, clock) as server, \
            ModbusEncoder(server.encoder_config(register=100, max_consecutive_errors=5), clock) as enc:
        enc.start()
        assert not enc.wait_for_samples(1, 10.0)  # woken by the fault, not by a sample
        with pytest.raises(EncoderFault, match=r"5 failed reads in a row.*exception reply 2 \(illegal data address\)") as err:
            enc.read()
        assert err.value.counts["exceptions"] == 5
        assert enc.stats()["exceptions"] == 5 and enc.stats()["samples"] == 0


def test_no_server_is_a_clear_fault_not_a_hang(clock):
    cfg = EncoderConfig(port=f"socket://127.0.0.1:{free_tcp_port()}", max_consecutive_errors=3, timeout=0.05)
    with ModbusEncoder(cfg, clock) as enc:
        enc.start()
        assert not enc.wait_for_samples(1, 10.0)
        with pytest.raises(EncoderFault, match="3 failed reads in a row.*cannot open the port"):
            enc.read()


def test_server_stopping_mid_capture_faults(clock):
    server = SimEncoderServer(wave, clock).start()
    try:
        with ModbusEncoder(server.encoder_config(max_consecutive_errors=4), clock) as enc:
            enc.start()
            assert enc.wait_for_samples(20, 10.0)
            server.stop()
            assert not enc.wait_for_samples(10**9, 10.0)
            with pytest.raises(EncoderFault, match="encoder fault: 4 failed reads in a row") as err:
                enc.read()
            assert err.value.counts["connection_errors"] >= 1
    finally:
        server.stop()


@pytest.mark.parametrize("layout", [
    dict(registers=1, counts_per_turn=1 << 12),
    dict(registers=2, word_order="little"),
    dict(direction=-1, zero=12345),
    dict(multi_turn=True, zero=-7),
])
def test_register_layouts_round_trip(clock, layout):
    """Whatever the encoder's layout, the client configured alike reads the same angle (across the 0 wrap too)."""
    cfg = SimEncoderConfig(**layout)
    omega = 2 * math.pi * 10.0  # fast enough to cross zero a few times in 600 samples at any bus speed

    def fast(t):
        return AMPLITUDE * math.sin(omega * t)
    with SimEncoderServer(fast, clock, cfg) as server, ModbusEncoder(server.encoder_config(), clock) as enc:
        reached, t, a = capture(enc, 600)
        assert reached
    quantum = 2 * math.pi / cfg.counts_per_turn
    truth = np.array([fast(x) for x in t])
    assert np.max(np.abs(a - truth)) <= omega * AMPLITUDE * enc.stats()["rtt_max_s"] / 2 + quantum
    assert (a < 0).any() and (a > 0).any()  # crossed the encoder's wrap without a 2π jump


def test_read_position_once(clock):
    with SimEncoderServer(lambda t: -0.5, clock) as server, ModbusEncoder(server.encoder_config(), clock) as enc:
        t, angle = enc.read_position()
        assert angle == pytest.approx(-0.5, abs=2 * math.pi / 2**17)
        assert t <= clock.now()


def test_counts_to_angle_wraps_to_the_nearest_turn():
    cfg = EncoderConfig(port="/dev/null", counts_per_turn=1000, zero=990)
    assert cfg.counts_to_angle(990) == 0.0
    assert cfg.counts_to_angle(0) == pytest.approx(2 * math.pi * 10 / 1000)
    assert cfg.counts_to_angle(980) == pytest.approx(-2 * math.pi * 10 / 1000)


def test_crc_check():
    good = bytes.fromhex("01 03 04 00 00 00 01 3b f3")
    assert not bad_crc(good)
    assert bad_crc(good[:-1] + b"\x00")
    assert not bad_crc(b"\x01\x03")


@pytest.mark.parametrize(("field", "value", "match"), [
    ("device_id", 0, "device_id"), ("device_id", 248, "device_id"), ("registers", 3, "registers"),
    ("counts_per_turn", 1 << 17, "counts_per_turn"), ("parity", "X", "parity"), ("timeout", 0, "timeout"),
    ("direction", 2, "direction"), ("register_type", "coil", "register_type"), ("word_order", "middle", "word_order"),
])
def test_encoder_settings_are_validated(field, value, match):
    kwargs = {"port": "/dev/ttyUSB0", field: value}
    if field == "counts_per_turn":
        kwargs["registers"] = 1
    with pytest.raises(DriverConfigError, match=match) as err:
        EncoderConfig(**kwargs)
    assert isinstance(err.value, InvalidInput)


def test_encoder_settings_from_a_toml_table():
    cfg = EncoderConfig.from_dict({"port": "/dev/ttyUSB0", "device_id": 3, "parity": "E"})
    assert cfg.device_id == 3 and cfg.parity == "E"
    with pytest.raises(DriverConfigError, match="unknown setting.*slave"):
        EncoderConfig.from_dict({"port": "/dev/ttyUSB0", "slave": 3})
    with pytest.raises(DriverConfigError, match="port"):
        EncoderConfig.from_dict({"device_id": 3})


def test_simulated_encoder_settings_are_validated():
    with pytest.raises(DriverConfigError, match="drop_rate"):
        SimEncoderConfig(drop_rate=1.5)
    with pytest.raises(DriverConfigError, match="latency"):
        SimEncoderConfig(latency=-1)


def test_back_to_back_captures_on_one_connection(clock):
    """stop() cancels a read in flight cleanly: the next capture starts afresh with zeroed counts."""
    with SimEncoderServer(wave, clock, SimEncoderConfig(drop_rate=0.1, seed=3)) as server, \
            ModbusEncoder(server.encoder_config(timeout=0.01, max_consecutive_errors=50), clock) as enc:
        for _ in range(3):
            reached, t, a = capture(enc, 100)
            assert reached and len(t) >= 100 and np.all(np.diff(t) > 0)
            assert enc.stats()["samples"] == len(t)
        assert enc.stats()["connection_errors"] == 0
