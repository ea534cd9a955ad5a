"""Experiment behind docs/measured-data.md: is the wood trace's residual a sensor gain?

Written before the library had its `gain` effect: this adds a gain g to the
final model by hand, θ_meas = g·θ + a, fits it, and prints the residual and BIC.
Run from the repository root: `.venv/bin/python docs/experiments/wood_sensor_gain.py`.
"""

import math
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares

from measurement import Rig
from measurement.fit import fit_model
from measurement.identification.preparation import prepare
from measurement.model import Model
from service.sources.files import read_trace

ROOT = Path(__file__).resolve().parents[2]


def main() -> None:
    trace = read_trace(ROOT / "data" / "wood_pendulum_60deg.csv")
    prep = prepare(trace)
    rig = Rig(kind="compound")
    for names in (["viscous", "coulomb"], ["viscous", "coulomb", "quadratic"]):
        model = Model.from_names(rig, names)
        fit = fit_model(model, prep.t, prep.y, prep.noise)
        nd = model.n_dynamic

        def residual(p: np.ndarray) -> np.ndarray:
            theta, _ = model.true_angle(p[:-1], prep.t, fit.max_step)
            return p[-1] * theta + p[nd] - prep.y

        lo, hi = model.bounds()
        sol = least_squares(residual, np.append(fit.x, 1.0), bounds=(np.append(lo, 0.3), np.append(hi, 3.0)),
                            x_scale="jac")
        n, k = prep.t.size, sol.x.size
        rss = float(sol.fun @ sol.fun)
        bic = n * math.log(rss / n) + k * math.log(n)
        values = dict(zip(model.names, sol.x))
        print(f"model {'+'.join(names)}: without gain RMS {fit.residual_rms:.4f} rad, BIC {fit.bic:.1f}; "
              f"with gain g = {sol.x[-1]:.4f}: RMS {math.sqrt(rss / n):.4f} rad, BIC {bic:.1f} (ΔBIC {bic - fit.bic:+.1f}); "
              f"omega_n {values['omega_n']:.4f} rad/s; "
              + ", ".join(f"{k} {v:.4g}" for k, v in values.items() if "." in k))


if __name__ == "__main__":
    main()
