"""Experiment behind docs/measured-data.md: do oblique-camera sensor laws reconcile the two wood sessions?

Adds two candidate sensor laws outside the library for this run only:
``foreshortening`` (θ_meas ≈ θ + e·½·sin 2θ, first order of atan2(κ·sin θ, cos θ))
and ``even`` (θ_meas = θ + b·(1 − cos θ), a marker line off the pivot), and
runs the discovery loop on both traces. Answer: each lowers BIC in one
session, but the two ω_n move further apart, so neither is the common cause.
Run from the repository root: `.venv/bin/python docs/experiments/wood_sensor_laws.py`.
"""

from pathlib import Path

import numpy as np

from measurement import identify
from measurement.effects import Effect, Parameter
from service.files import read_rig, read_trace

ROOT = Path(__file__).resolve().parents[2]


class Foreshortening(Effect):
    name = "foreshortening"
    role = "sensor"
    rigs = ("compound",)
    parameters = (Parameter("e", "1", None, None, lower=-np.inf),)

    def sensor_basis(self, t, theta):
        return (0.5 * np.sin(2 * theta))[:, None]


class Even(Effect):
    name = "even"
    role = "sensor"
    rigs = ("compound",)
    parameters = (Parameter("b", "1", None, None, lower=-np.inf),)

    def sensor_basis(self, t, theta):
        return (1 - np.cos(theta))[:, None]


def main() -> None:
    rig = read_rig(ROOT / "examples" / "wood_pendulum.toml")
    for name in ("wood_pendulum_60deg.csv", "wood_pendulum_120deg.csv"):
        r = identify(read_trace(ROOT / "data" / name), rig)
        print(f"{name}: effects {', '.join(r.effects)}; omega_n {r.omega_n:.5f} ± {r.omega_n_std:.5f} rad/s;"
              f" residual {r.residual_rms / r.noise_floor:.2f} × noise; flags {', '.join(r.flags)}")
        for st in r.steps:
            print(f"  round {st.round}: {st.chosen or 'nothing'} added; tried "
                  + ", ".join(f"{k} {v['bic'] - st.bic_before:+.1f}" for k, v in st.candidates.items()))


if __name__ == "__main__":
    main()
