"""Experiment behind docs/measured-data.md: how much does each session's ω_n rest on the sensor law?

Fits both wood traces with the same physics (viscous, dahl, quadratic) and
each sensor law of the library (none, gain, view), without discovery, and
prints ω_n, the residual and BIC. The 120° session (swings 2.2 → 0.5 rad)
pins its scale: its ω_n hardly moves. The 60° session (1 rad and less)
cannot tell its scale from the amplitude dependence of the frequency: its
ω_n moves by 0.7 %. Run from the repository root:
`.venv/bin/python docs/experiments/wood_sensor_laws.py`.
"""

from dataclasses import replace
from pathlib import Path

from measurement import Options, identify
from service.sources.files import read_rig, read_trace

ROOT = Path(__file__).resolve().parents[2]
PHYSICS = ("viscous", "dahl", "quadratic")


def main() -> None:
    rig = read_rig(ROOT / "examples" / "wood_pendulum.toml")
    for name in ("wood_pendulum_60deg.csv", "wood_pendulum_120deg.csv"):
        trace = read_trace(ROOT / "data" / name)
        print(name)
        for law in ((), ("gain",), ("view",)):
            r = identify(trace, replace(rig, declared=PHYSICS + law), Options(discover=False))
            print(f"  sensor law {law[0] if law else 'none':<5} omega_n {r.omega_n:.4f} ± {r.omega_n_std:.4f} rad/s,"
                  f" residual {r.residual_rms / r.noise_floor:.2f} × noise, BIC {r.baseline.bic:.1f}")


if __name__ == "__main__":
    main()
