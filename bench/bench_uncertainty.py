"""Is the uncertainty budget honest? Coverage of J_object ± J_object_U over calibrate-then-measure repeats.

Each repeat calibrates the example torsion rig (k = 0.3651 N·m/rad, I0 = 4.5043e-3 kg·m²) as the docs
recommend, each of three references (the empty fixture and two discs) released twice (six simulated swings),
their certified inertias off their true values by an error drawn from the certificate's σ (0.4 % and 0.5 %),
fits k, I0 and their covariance (`measurement.calibration`) and pools the references' releases into the rig's
reproducibility (kept with its calibration, ν = 3), then measures a part (true J_object = 0.010 kg·m²) on the
same rig: its one release counts the rig's figure. For contrast the same release on the rig without the figure
(the documented default counted). A true
budget covers the truth in about 95 % of the repeats (goal 93–97 %) and is not inflated. For a normal
error and U = k·u the median U over the RMS error is k when u is right (2 for k = 2); the bench prints it
and its ratio to k (1 when honest; goal ≤ 1.5: at most 50 % wider than it needs to be).

Run: `.venv/bin/python bench/bench_uncertainty.py [REPEATS]` (default 200; at least 40), or `make bench`.

Reproducibility between releases: `.venv/bin/python bench/bench_uncertainty.py --remount REL [REPEATS]` gives
every release a scatter the record cannot see (the pivot settling: k off by a relative 2·REL, normal, drawn
anew for each release, so ω_n scatters by REL), measures a check standard (the 0.0125 kg·m² disc) HISTORY
times to pool it (``measurement.reproducibility.pooled``), and prints the part's coverage with the rig's
history in u and without it (one release on a rig whose calibration keeps no figure: the default counted).
"""

from __future__ import annotations

import datetime as dt
import math
import statistics
import sys
import time
from dataclasses import replace

import numpy as np

from measurement import Options, Pendulum, Rig, identify, simulate_trace
from measurement.calibration import Reference, calibrate_torsion, reproducibility
from measurement.identification.quantities import budgets
from measurement.reproducibility import DEFAULT, pooled
from measurement.rig import CalibrationRecord

K, I0 = 0.3651, 4.5043e-3
LOADS = (0.0, 0.005, 0.0125)          # true added inertias, kg·m²
CERT_REL = (0.0, 0.004, 0.005)        # certificates' relative 1σ (the empty fixture adds exactly nothing)
PART = 0.010                          # true J_object of the part, kg·m²
DAMPING = {"viscous": {"c": 2e-4}}


def swing(rig: Rig, J: float, seed: int):
    return simulate_trace(Pendulum(rig, J, DAMPING), theta0=0.3, duration=10.0, rate=100.0, noise_std=2e-4,
                          seed=seed)


#: releases of each reference in the main run's calibration
REF_RELEASES = 2


def repeat(i: int) -> tuple[float, float, float, float, float]:
    """(error of J_object, its U with the rig's calibration figure, its coverage factor, the U a calibration from
    the misfit alone would give, the U with the default counted instead) of one calibrate-then-measure repeat,
    kg·m²."""
    rng = np.random.default_rng(1000 + i)
    true_rig = Rig(kind="torsion", stiffness=K, declared=("viscous",))
    refs = []
    for j, (load, rel) in enumerate(zip(LOADS, CERT_REL)):
        u = rel * load
        certified = load + (rng.normal(0.0, u) if u else 0.0)  # one certificate, whatever the releases
        for n in range(REF_RELEASES):
            seed = 10 * i + j if n == 0 else 100_000 + 10 * i + j
            r = identify(swing(true_rig, I0 + load, seed), Rig(kind="torsion", declared=("viscous",)), Options())
            refs.append(Reference(f"ref {j}", certified, r.omega_n, r.omega_n_u or r.omega_n_std, u))
    cal = calibrate_torsion(refs)
    figure = reproducibility(refs)
    assert figure is not None and figure.relative is not None
    record = CalibrationRecord(dt.date(2026, 1, 1), None, tuple({"name": r.name} for r in refs), None,
                               reproducibility=figure.relative, reproducibility_dof=int(figure.dof))
    rig = Rig(kind="torsion", stiffness=cal.stiffness, stiffness_std=cal.stiffness_std, tare_inertia=cal.tare_inertia,
              tare_inertia_std=cal.tare_inertia_std, stiffness_tare_covariance=cal.covariance, declared=("viscous",),
              calibration=record)
    res = identify(swing(true_rig, I0 + PART, 10 * i + 9), rig, Options())
    assert res.reproducibility is not None and res.reproducibility.source == "rig"
    b = res.uncertainty_budget["J_object"]
    default_b = budgets(replace(rig, calibration=None), res.omega_n, res.omega_n_std, dof=b.dof,
                        model=res.omega_n_std_model, reproducibility=DEFAULT)["J_object"]
    # the same references without their σ: k and I0's σ from the misfit alone
    old = calibrate_torsion([Reference(r.name, r.added_inertia, r.omega_n) for r in refs])
    old_rig = Rig(kind="torsion", stiffness=old.stiffness, stiffness_std=old.stiffness_std,
                  tare_inertia=old.tare_inertia, tare_inertia_std=old.tare_inertia_std,
                  stiffness_tare_covariance=old.covariance, declared=("viscous",))
    old_b = budgets(old_rig, res.omega_n, res.omega_n_std, model=res.omega_n_std_model,
                    reproducibility=res.reproducibility)["J_object"]
    return b.value - PART, b.U, b.coverage_factor, old_b.U, default_b.U


#: check-standard releases pooled into the rig's history in the remount runs
HISTORY = 5


def remount_repeat(i: int, rel: float) -> tuple[float, float, float]:
    """(error of J_object, its U with the rig's pooled history in u, its U without) of one release on a rig
    whose releases scatter by ``rel`` in ω_n, on a calibration from the true inertias (kg·m²)."""
    rng = np.random.default_rng(5000 + i)

    def settled() -> Rig:  # a release's own stiffness: the pivot settled anew
        return Rig(kind="torsion", stiffness=K * (1 + 2 * rel * rng.normal()), declared=("viscous",))

    rig = Rig(kind="torsion", stiffness=K, stiffness_std=K * 1e-4, tare_inertia=I0, tare_inertia_std=1e-7,
              declared=("viscous",))
    checks = [identify(swing(settled(), I0 + LOADS[2], 100 * i + j), rig, Options()).J for j in range(HISTORY)]
    history = pooled([[float(J) for J in checks if J is not None]], power=-2)
    trace = swing(settled(), I0 + PART, 100 * i + 99)
    alone = identify(trace, rig, Options()).uncertainty_budget["J_object"]
    counted = identify(trace, rig, Options(reproducibility=history)).uncertainty_budget["J_object"]
    return alone.value - PART, counted.U, alone.U


def main_remount(repeats: int, rel: float) -> None:
    t0 = time.perf_counter()
    rows = np.array([remount_repeat(i, rel) for i in range(repeats)])
    err = np.abs(rows[:, 0])
    print(f"{repeats} releases on a rig whose releases scatter {100 * rel:.2g} % in ω_n, history of {HISTORY} "
          f"check-standard releases, {time.perf_counter() - t0:.0f} s")
    for name, col in (("the rig's history in u", 1), ("one release, the default counted", 2)):
        print(f"  {name}: coverage {int(np.sum(err <= rows[:, col]))}/{repeats} = {100 * np.mean(err <= rows[:, col]):.1f} %,"
              f" median U {statistics.median(rows[:, col]):.3g} kg·m²")


def main(repeats: int = 200) -> None:
    t0 = time.perf_counter()
    rows = [repeat(i) for i in range(repeats)]
    err = np.array([r[0] for r in rows])
    U = np.array([r[1] for r in rows])
    covered = int(np.sum(np.abs(err) <= U))
    rms = math.sqrt(float(np.mean(err**2)))
    ratio = statistics.median(U) / rms
    # the binomial 95 % range of the coverage count for a true 95 % interval
    lo, hi = np.quantile(np.random.default_rng(0).binomial(repeats, 0.9545, 100_000), [0.025, 0.975])
    print(f"{repeats} calibrate-then-measure repeats (3 references released {REF_RELEASES} times each, certificates "
          f"0.4–0.5 %, part J_object = {PART} kg·m²; the part's release counts the rig's calibration figure), "
          f"{time.perf_counter() - t0:.0f} s")
    print(f"  coverage of J_object ± J_object_U: {covered}/{repeats} = {100 * covered / repeats:.1f} % "
          f"(goal 93–97 %; a true 95.45 % interval gives {int(lo)}–{int(hi)} of {repeats} in 95 % of such runs)")
    k = statistics.median(r[2] for r in rows)
    print(f"  median U {statistics.median(U):.3g} kg·m² ({100 * statistics.median(U) / PART:.2f} %), RMS error "
          f"{rms:.3g} kg·m²: median U / RMS error = {ratio:.2f}, over k = {k:.2f}: {ratio / k:.2f} "
          f"(1 when honest, goal ≤ 1.5)")
    print(f"  U spread over the repeats: {U.min():.3g} … {U.max():.3g} kg·m² (max/min {U.max() / U.min():.2f})")
    old = np.array([r[3] for r in rows])
    print(f"  for contrast, k and I0's σ from the misfit alone (the references' σ ignored): coverage "
          f"{100 * np.mean(np.abs(err) <= old):.1f} %, U {old.min():.2g} … {old.max():.2g} kg·m² "
          f"(max/min {old.max() / old.min():.0f})")
    dflt = np.array([r[4] for r in rows])
    print(f"  for contrast, the same releases with the documented default counted (a rig file without the figure): "
          f"coverage {100 * np.mean(np.abs(err) <= dflt):.1f} %, median U / RMS error "
          f"{statistics.median(dflt) / rms:.2f}")


if __name__ == "__main__":
    if len(sys.argv) > 2 and sys.argv[1] == "--remount":
        main_remount(int(sys.argv[3]) if len(sys.argv) > 3 else 40, float(sys.argv[2]))
    else:
        main(int(sys.argv[1]) if len(sys.argv) > 1 else 200)
