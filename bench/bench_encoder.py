"""Encoder client against the simulated encoder server: samples per second and timestamp jitter.

The server emulates a 115200-baud RS-485 line (the wire time of each 8-byte
request and 9-byte reply, 10 bits per character) plus a 0.3 ms encoder
turnaround, on loopback TCP. The angle is a fast ramp (20 rad/s), so the
time at which the server latched each position is known from the position
itself: the timestamp error of each sample is t_host_midpoint − t_latch.

    rate            samples per second (wall clock = simulated clock here, scale 1)

Then the simulated appliance's own encoder (``service.devices.hardware.build_simulated``:
default latency, noise and late-reply rule) at each allowed time scale:
requests and kept samples per wall-clock second, samples per simulated second
(what a capture gets), and the share of late replies dropped.
    dt std          spread of the sample intervals (how even the sampling is)
    stamp bias/std  mean and standard deviation of t_midpoint − t_latch; the std is
                    the timestamp jitter that matters for the fit (a constant bias
                    only shifts the trace in time)
"""

from __future__ import annotations

import logging
import math
import time

import numpy as np

RAMP = 20.0  # rad/s


def ramp_capture(seconds: float, ramp: float, server: dict, encoder: dict) -> tuple[np.ndarray, np.ndarray, dict]:
    """(host time stamps, angles, the client's stats) of the encoder client reading a simulated encoder whose
    angle is a ramp of ``ramp`` rad/s for ``seconds`` of wall clock (scale 1): the position tells the latch time.
    ``server``: ``SimEncoderConfig`` keywords; ``encoder``: ``encoder_config`` keywords."""
    from drivers.clock import ScaledClock
    from drivers.encoder import ModbusEncoder
    from drivers.sim_encoder import SimEncoderConfig, SimEncoderServer

    clock = ScaledClock(1.0)
    with SimEncoderServer(lambda t: ramp * t, clock, SimEncoderConfig(**server)) as srv, \
            ModbusEncoder(srv.encoder_config(**encoder), clock) as enc:
        enc.start()
        t_end = time.perf_counter() + seconds
        while time.perf_counter() < t_end:  # a bench may wait on the wall clock: that is what it measures
            time.sleep(0.05)
        enc.stop()
        t, angle = enc.read()
        return t, angle, enc.stats()


def run(label: str, seconds: float, **server_kwargs) -> dict:
    t, angle, stats = ramp_capture(seconds, RAMP, {"baudrate": 115200, "latency": 0.0003, **server_kwargs},
                                   {"timeout": 0.02, "max_consecutive_errors": 100})
    # the ramp makes the latch time readable from the position (unwrapped by the client)
    t_latch = angle / RAMP
    err = t - t_latch
    err = err - np.median(err)  # the ramp's start offset is unknown; keep the spread
    dt = np.diff(t)
    bias = float(np.mean(t - t_latch) - np.median(t - t_latch))
    row = {
        "label": label, "samples": len(t), "rate": len(t) / (t[-1] - t[0]),
        "dt_mean_ms": 1e3 * float(dt.mean()), "dt_std_ms": 1e3 * float(dt.std()),
        "dt_p99_ms": 1e3 * float(np.percentile(dt, 99)),
        "stamp_std_us": 1e6 * float(err.std()), "stamp_p99_us": 1e6 * float(np.percentile(np.abs(err), 99)),
        "stamp_mean_minus_median_us": 1e6 * bias,
        "timeouts": stats["timeouts"], "crc_errors": stats["crc_errors"],
        "rtt_max_ms": 1e3 * stats["rtt_max_s"],
    }
    return row


def main() -> None:
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)
    wire = (8 + 9) * 10 / 115200
    print(f"simulated encoder at 115200 baud: wire time {wire * 1e3:.2f} ms per read + 0.3 ms turnaround "
          f"→ bus limit {1 / (wire + 0.0003):.0f} reads/s; loopback TCP, same process")
    rows = [
        run("clean", 3.0),
        run("5 % dropped, 1 % CRC", 3.0, drop_rate=0.05, crc_error_rate=0.01, seed=1),
    ]
    for r in rows:
        print(f"{r['label']:>22}: {r['rate']:7.0f} samples/s ({r['samples']} in 3 s); "
              f"interval {r['dt_mean_ms']:.3f} ms ± {r['dt_std_ms']:.3f} (p99 {r['dt_p99_ms']:.2f} ms); "
              f"timestamp jitter σ {r['stamp_std_us']:.0f} µs (p99 |err| {r['stamp_p99_us']:.0f} µs); "
              f"rtt max {r['rtt_max_ms']:.1f} ms; timeouts {r['timeouts']}, CRC errors {r['crc_errors']}")
    clean = rows[0]
    print(f"angle error from timestamp jitter on a 0.25 rad, 0.86 Hz swing: "
          f"≤ {0.25 * 2 * math.pi * 0.86 * clean['stamp_std_us'] * 1e-6:.2e} rad RMS")
    main_scales()


def per_time_scale(seconds: float = 2.0) -> list[dict]:
    """Samples per simulated second of the simulated appliance's encoder at each allowed time scale."""
    from firmware_host import SequencerConfig
    from service.devices.hardware import build_simulated
    from service.settings.config import SimulationSettings
    from service.settings.defaults import DEMO_RIG, MAX_ENCODER_TIME_SCALE, SIM_ENCODER_NOISE

    logging.getLogger("moi.hardware").setLevel(logging.ERROR)  # the faster-than-real-time warning, once per scale
    rows = []
    for scale in (1.0, 2.0, 5.0, 10.0, MAX_ENCODER_TIME_SCALE):
        sim = SimulationSettings(time_scale=scale, noise=SIM_ENCODER_NOISE, sensor="encoder", seed=1)
        with build_simulated(DEMO_RIG, sim, SequencerConfig(capture_duration=seconds * scale)) as dev:
            dev.sensor.start()
            time.sleep(seconds)  # a bench may wait on the wall clock: that is what it measures
            dev.sensor.stop()
            t, _ = dev.sensor.read()
            st = dev.sensor.stats()
        rows.append({"scale": scale, "requests_per_s": st["requests"] / seconds, "samples_per_s": len(t) / seconds,
                     "samples_per_sim_s": len(t) / (seconds * scale),
                     "late_share": st["late_replies"] / max(st["requests"], 1)})
    return rows


def main_scales() -> None:
    print("the simulated appliance's encoder per time scale (2 s of wall time each):")
    for r in per_time_scale():
        print(f"  time × {r['scale']:4g}: {r['requests_per_s']:6.0f} requests/s, {r['samples_per_s']:6.0f} samples/s "
              f"(wall) → {r['samples_per_sim_s']:6.1f} samples per simulated s; late replies dropped "
              f"{100 * r['late_share']:4.1f} %")


if __name__ == "__main__":
    main()
