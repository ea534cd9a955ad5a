"""Identification speed and accuracy.

Targets on this 2-core machine: declared-model fit of a 30 s, 200 Hz trace
under 1 s (so a Raspberry Pi 4 stays under 5 s); the whole discovery loop
under 3 s. Run: `.venv/bin/python bench/bench_identify.py` (or `make bench`).
"""

import datetime as dt
import statistics
import time

from measurement import Options, Pendulum, Rig, identify, simulate_trace
from measurement.rig import CalibrationRecord

K, J = 0.3651, 0.0125
CASES = {
    "viscous (clean)": {"viscous": {"c": 1.5e-4}},
    "viscous + coulomb": {"viscous": {"c": 1e-4}, "coulomb": {"Tc": 1.5e-4}},
    "viscous + quadratic": {"viscous": {"c": 1e-4}, "quadratic": {"K": 2e-3}},
    "viscous + cubic spring": {"viscous": {"c": 1e-4}, "cubic_stiffness": {"k3": 0.5}},
    "viscous + drift": {"viscous": {"c": 1e-4}, "drift": {"rate": 3e-4}},
}


def timed(fn, repeat=3):
    times, out = [], None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return out, min(times), statistics.median(times)


def main():
    # K is the simulated spring's small-swing stiffness: a calibration read at zero amplitude (J takes ω there)
    rig = Rig(kind="torsion", stiffness=K, declared=("viscous",),
              calibration=CalibrationRecord(dt.date(2026, 1, 5), amplitude=0.0))
    print("30 s at 200 Hz (6000 samples), noise 1e-4 rad, 17-bit encoder; declared = viscous")
    print(f"{'case':<26}{'declared fit [s]':>17}{'whole loop [s]':>16}{'added':>18}{'J error':>13}{'J_std':>11}")
    for name, effects in CASES.items():
        trace = simulate_trace(Pendulum(rig, J, effects), theta0=0.25, duration=30, rate=200, noise_std=1e-4,
                               quantisation_bits=17, seed=11)
        _, fit_min, _ = timed(lambda: identify(trace, rig, Options(discover=False)))
        r, loop_min, _ = timed(lambda: identify(trace, rig))
        print(f"{name:<26}{fit_min:>17.2f}{loop_min:>16.2f}{','.join(r.added_effects) or '-':>18}"
              f"{1e6 * (r.J / J - 1):>+9.2f} ppm{1e6 * r.J_std / J:>7.2f} ppm")
    # the compound pendulum of Hou Wen, "Measuring Moment of Inertia Based on Identification of Nonlinear System
    # Featuring Naught Excitation" (WSEAS 2006), Fig. 3 (declared coulomb + quadratic)
    crig = Rig(kind="compound", mass=500.0, com_distance=1.0, g=9.8, declared=("coulomb", "quadratic"))
    trace = simulate_trace(Pendulum(crig, 1000.0, {"coulomb": {"mu": 0.01}, "quadratic": {"K": 10.0}}), theta0=-0.5,
                           duration=30, rate=200, noise_std=1e-4, quantisation_bits=17, seed=3)
    r, loop_min, _ = timed(lambda: identify(trace, crig))
    print(f"{'Hou 2006 Fig. 3':<26}{'':>17}{loop_min:>16.2f}{','.join(r.added_effects) or '-':>18}"
          f"{1e6 * (r.J / 1000 - 1):>+9.2f} ppm{1e6 * r.J_std / 1000:>7.2f} ppm  "
          f"mu {r.damping['coulomb']['mu'].value:.5f} m, K {r.damping['quadratic']['K'].value:.3f} N·m·s²")
    from pathlib import Path

    from service.sources.files import read_rig, read_trace
    root = Path(__file__).resolve().parents[1]
    rig_wood = read_rig(root / "examples" / "wood_pendulum.toml")
    for name in ("wood_pendulum_60deg.csv", "wood_pendulum_120deg.csv"):
        wood = read_trace(root / "data" / name)
        r, loop_min, _ = timed(lambda: identify(wood, rig_wood), repeat=1)
        print(f"{'measured ' + name[14:-4]:<26}{'':>17}{loop_min:>16.2f}{','.join(r.added_effects) or '-':>18}"
              f"   omega_n {r.omega_n:.4f} ± {r.omega_n_std:.4f} rad/s, flags {','.join(r.flags)}")

if __name__ == "__main__":
    main()
