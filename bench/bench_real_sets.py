"""Releases of one object recorded by other people: each release's ω_n ± u, the joint value and the consistency test.

The sets in data/ (wooden pendulum filmed in two sessions, as tracked and
with the camera's view measured from two markers; a cart pendulum on an
encoder, four releases from 21° to 179°; a bifilar suspension read by an
IMU, two releases). Whatever the release angle or sensor, the releases of
one object must agree within the uncertainty moi states for each: the
largest normalised pairwise difference (goal ≤ 2) and the joint fit's χ²
test (goal p ≥ 0.01) say whether they do.

    .venv/bin/python bench/bench_real_sets.py
"""

from __future__ import annotations

import time
from pathlib import Path

from measurement.joint import identify_releases
from service.sources.dispatch import load_source
from service.sources.files import read_rig

ROOT = Path(__file__).resolve().parents[1]
SETS = [
    ("cart pendulum (encoder)", [f"data/cart_pendulum_{a}deg.csv" for a in (20, 40, 80, 180)], "examples/cart_pendulum.toml"),
    ("bifilar suspension (IMU)", [f"data/bifilar_yaw_{a}deg.csv" for a in (65, 86)], "examples/bifilar_yaw.toml"),
    ("wood pendulum, as tracked", [f"data/wood_pendulum_{a}deg.csv" for a in (60, 120)], "examples/wood_pendulum.toml"),
    ("wood pendulum, view measured", [f"data/wood_markers_{a}deg.csv" for a in (60, 120)], "examples/wood_pendulum.toml"),
]


def main() -> None:
    print("releases of one object: ω_n of each release alone (its own model) ± combined u, and the joint value")
    for name, files, rig in SETS:
        t0 = time.perf_counter()
        j = identify_releases([load_source(ROOT / f) for f in files], read_rig(ROOT / rig))
        took = time.perf_counter() - t0
        print(f"\n{name}  ({took:.1f} s)")
        print(f"  {'release':<28}{'ω_n [rad/s]':>13}{'u':>10}{'σ fit':>10}{'model form':>12}  effects; flags")
        for r in j.releases:
            print(f"  {Path(r.source).name:<28}{r.omega_n:>13.6f}{r.omega_n_u:>10.2g}{r.omega_n_std:>10.2g}"
                  f"{r.omega_n_std_model:>12.2g}  {', '.join(r.effects)}; "
                  f"{', '.join(f for f in r.flags if f not in ('correlated_residual', 'outliers_removed')) or '-'}")
        c = j.consistency
        spread = (max(r.omega_n for r in j.releases) - min(r.omega_n for r in j.releases)) / j.omega_n
        print(f"  joint ω_n {j.omega_n:.6f} ± {j.omega_n_u:.2g} rad/s (joint fit {c['joint_fit']['omega_n']:.6f}); "
              f"spread {100 * spread:.3f} %; largest pairwise difference {c['pairwise_max']:.2f} σ (goal ≤ 2); "
              f"χ² {c['chi2']:.2f} on {c['dof']}, p = {c['p']:.2g} (goal ≥ 0.01)")


if __name__ == "__main__":
    main()
