"""Experiment behind docs/measured-data.md: where do the two wood sessions disagree?

1. Model-free: for every full period (zero crossing i to i+2) the swing
   frequency ω, and ω_n implied by it after removing the exact sin θ period
   lengthening at the measured amplitude A: ω_n = ω·(2/π)·K(sin²(A/2)).
   If the model (sin θ restoring, sensor reads θ) holds, this is constant.
2. The same identification on the amplitudes both sessions share: the 60°
   record up to 12 s (A ≥ 0.4 rad), the 120° record after 17 s (A ≤ 0.95 rad).
Run from the repository root: `.venv/bin/python docs/experiments/wood_frequency_vs_amplitude.py`.
"""

import math
from pathlib import Path

import numpy as np
from scipy.special import ellipk

from measurement import Trace, identify
from measurement.identification.preparation import prepare
from measurement.signal import find_swings
from service.sources.files import read_rig, read_trace

ROOT = Path(__file__).resolve().parents[2]


def main() -> None:
    rig = read_rig(ROOT / "examples" / "wood_pendulum.toml")
    traces = {name: read_trace(ROOT / "data" / f"wood_pendulum_{name}.csv") for name in ("60deg", "120deg")}
    for name, trace in traces.items():
        prep = prepare(trace)
        sw = find_swings(prep.t, prep.y, hysteresis=3 * prep.noise)
        c, pk = sw.crossings, np.abs(sw.peak_values)
        print(f"{name}: t [s], amplitude A [rad], ω [rad/s], ω_n with sin θ removed [rad/s]")
        for i in range(0, min(c.size - 2, pk.size - 2), 4):
            w = 2 * math.pi / (c[i + 2] - c[i])
            a = 0.5 * (pk[i + 1] + pk[i + 2])
            print(f"  {c[i]:6.2f} {a:6.3f} {w:8.4f} {w * 2 / math.pi * ellipk(math.sin(a / 2) ** 2):8.4f}")
    for name, keep in (("60deg", lambda t: t < 12.0), ("120deg", lambda t: t > 17.0)):
        tr = traces[name]
        k = keep(tr.t)
        r = identify(Trace(tr.t[k], tr.angle[k], source=name), rig)
        print(f"{name}, shared amplitudes only: effects {', '.join(r.effects)}; "
              f"omega_n {r.omega_n:.4f} ± {r.omega_n_std:.4f} rad/s; flags {', '.join(r.flags)}")


if __name__ == "__main__":
    main()
