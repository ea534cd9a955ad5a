"""Does the fit's σ of ω_n cover the simulated encoder's time-stamp errors? What they are, and what they do to ω_n.

The simulated appliance reads its encoder over a real Modbus RTU link on loopback, in wall-clock time, and dates
each sample on the host at the midpoint of request and reply (drivers/encoder.py; replies too late to date are
dropped). Part 1 records those dates as the simulated appliance takes them (200 requests per second, 17 bits,
the default latency and late-reply rule) against a ramp, whose position says when the encoder latched: the
time-stamp error of every sample, its spread, and its slow part (the mean of each second, the linear drift over
the capture, ppm), which a white or autoregressive noise model of the angle cannot see: a stamp bias that moves
by Δ over a capture of T seconds scales the time axis by Δ/T, as a slow clock would.

Part 2 replays each recorded capture: the demo rig's swing (true J, its effects, 17-bit noise) sampled at the
latch times and stamped with the recorded host times, identified with and without the stamp errors (same
samples, same noise). Printed: ω_n's error, its u (the fit's σ, with the model-form part when there is one) and
z = error/u per capture, z against the fit's σ alone, and the rms z of each set. rms z ≈ 1 says u covers the
error; well above 1 that it does not. The fit's σ takes in the stamps' jitter and their wander over seconds
(measurement/fit.py ``score_variance``: the record's own residual, one stretch left out at a time); their
linear drift over the capture scales the time axis as a slow clock would, which no residual shows. The rig's ``clock_accuracy_ppm`` (the sample clock's 1σ in J's budget, 20 ppm for the demo rig)
is printed beside the drift: it is the budget line a time-scale error falls under.

Run: `.venv/bin/python bench/bench_stamp_drift.py [CAPTURES] [SECONDS]` (default 7 captures of 31 s, some
4 minutes), or `make bench`. Wall-clock: the figures depend on how busy the host is (print `uptime` with them).
"""

from __future__ import annotations

import logging
import math
import sys
from pathlib import Path

import numpy as np

#: rad/s of the ramp: 9.6 µs of time per count at 17 bits; a gap under 0.6 s (half a turn) unwraps right
RAMP = 5.0
#: the simulated appliance's request rate, Hz ([simulation] rate)
RATE = 200.0
#: the part of a capture the replay uses: the demo's 0.5 s pre-trigger and 30 s swing
PRE, SWING = 0.5, 30.0


def record(seconds: float) -> tuple[np.ndarray, np.ndarray]:
    """(host time stamps from the first, their errors against the latch times), s, of one capture."""
    from bench_encoder import ramp_capture

    from service.devices.sensors.encoder import SIM_ENCODER_TIMEOUT

    t, angle, _ = ramp_capture(seconds, RAMP, {"counts_per_turn": 1 << 17, "registers": 2, "latency": 0.0002},
                               {"timeout": SIM_ENCODER_TIMEOUT, "min_interval": 1.0 / RATE,
                                "max_consecutive_errors": 1000})
    turn = 2.0 * math.pi / RAMP  # a longer gap unwraps a whole turn off: folded back
    err = t - angle / RAMP
    err = (err - np.median(err) + turn / 2) % turn - turn / 2
    return t - t[0], err


def describe(t: np.ndarray, err: np.ndarray) -> str:
    blocks = [float(err[(t >= a) & (t < a + 1.0)].mean()) for a in range(int(t[-1])) if ((t >= a) & (t < a + 1.0)).any()]
    slope = float(np.polyfit(t, err, 1)[0])
    return (f"{t.size} samples over {t[-1]:.1f} s; stamp error σ {1e6 * err.std():.0f} µs (median |err| "
            f"{1e6 * np.median(np.abs(err)):.0f} µs); means of each second: σ {1e6 * np.std(blocks):.0f} µs, range "
            f"{1e6 * (max(blocks) - min(blocks)):.0f} µs; linear drift {1e6 * slope:+.2f} ppm")


def replay(t: np.ndarray, err: np.ndarray, seed: int) -> dict[str, tuple[float, float, float, float]]:
    """ω_n's (error, u, the fit's σ, true value), rad/s, of the demo swing sampled at the latch times, with and
    without the stamp errors."""
    from measurement import Options, Pendulum, identify
    from measurement.simulate import quantise
    from measurement.trace import Trace
    from service.settings.defaults import DEMO_EFFECTS, DEMO_INERTIA, DEMO_RIG, DEMO_THETA0, SIM_ENCODER_NOISE

    keep = t <= PRE + SWING
    stamped, latch = t[keep], t[keep] - err[keep]
    pendulum = Pendulum(DEMO_RIG, DEMO_INERTIA, DEMO_EFFECTS)
    theta = np.full(latch.size, DEMO_THETA0)
    free = latch >= PRE
    theta[free], _ = pendulum.motion(latch[free] - PRE, DEMO_THETA0, 0.0)
    angle = quantise(theta + np.random.default_rng(seed).normal(0.0, SIM_ENCODER_NOISE, latch.size), 17)
    out = {}
    for what, times in (("with", stamped), ("without", latch)):
        order = np.argsort(times, kind="stable")
        s, a = times[order], angle[order]
        distinct = np.concatenate([[True], np.diff(s) > 1e-6])
        r = identify(Trace(s[distinct] - s[distinct][0], a[distinct], source="replay"), DEMO_RIG, Options())
        e = r.omega_n - pendulum.omega_n
        out[what] = (e, r.omega_n_u or r.omega_n_std, r.omega_n_std, pendulum.omega_n)
    return out


def main(captures: int = 7, seconds: float = 31.0) -> None:
    from service.settings.defaults import DEMO_RIG

    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)
    print(f"the simulated appliance's encoder, {captures} captures of {seconds:g} s (requests at {RATE:g} Hz); "
          f"the demo rig's clock_accuracy_ppm: {DEMO_RIG.clock_accuracy_ppm:g}")
    clock = 1e-6 * (DEMO_RIG.clock_accuracy_ppm or 0.0)
    z: dict[str, list[float]] = {"with": [], "without": [], "fit with": [], "fit without": [], "budget": []}
    for i in range(captures):
        t, err = record(seconds)
        print(f"  capture {i + 1}: {describe(t, err)}")
        for what, (e, u, s, omega) in replay(t, err, seed=100 + i).items():
            z[what].append(e / u)
            z[f"fit {what}"].append(e / s)
            print(f"      {what:>7} the stamp errors: ω_n error {e:+.2e} rad/s ({1e6 * e / omega:+.2f} ppm), "
                  f"u {u:.2e} rad/s, z {e / u:+.2f}; the fit's σ {s:.2e} rad/s, z {e / s:+.2f}")
            if what == "with":  # against u and the sample clock's line of J's budget together
                z["budget"].append(e / math.hypot(u, clock * omega))
    rms = {what: math.sqrt(float(np.mean(np.square(zs)))) for what, zs in z.items()}
    print(f"rms z with the recorded stamp errors: {rms['with']:.2f}, without: {rms['without']:.2f} "
          f"(over {captures} captures); against the fit's σ alone: {rms['fit with']:.2f}, without: "
          f"{rms['fit without']:.2f}; with them against u and the sample clock's {1e6 * clock:g} ppm together: "
          f"{rms['budget']:.2f} (largest |z| {max(map(abs, z['budget'])):.2f})")


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 7, float(sys.argv[2]) if len(sys.argv) > 2 else 31.0)
