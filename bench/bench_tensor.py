"""The inertia tensor of a multi-orientation set: are its uncertainties honest, and how long is the wait?

Over seeded simulated sets of the example bracket (the default six orientations and the nine of
``TensorPlan.nine``, the centre of mass off the swing axis in some), the share of tensor
components within 2σ of the truth (goal 93–97 %: a Gaussian gives 95.4 %; below, the stated
uncertainty is too small; above, too large), and the share of principal axes within their stated
angle. Time: what the operator waits for after the last release of a set, that release's
identification plus the tensor (goal ≤ 0.5 s on the Pi proxy), median of several runs; run
pinned with `taskset -c 0 .venv/bin/python bench/bench_tensor.py` for the Pi proxy.
"""

import statistics
import time
from dataclasses import replace

import numpy as np

from measurement import identify
from measurement import tensor as TS
from measurement.rig import Rig
from measurement.simulate import BRACKET, RigidBody, simulate_set
from measurement.tensor import Orientation, TensorPlan

RIG = Rig(kind="torsion", stiffness=0.3651, tare_inertia=4.5e-3, declared=("viscous",))
OFFSETS = {"x": (0.0, 0.03, -0.02), "xz": (0.01, 0.025, 0.0), "x-y-z": (0.02, -0.01, 0.015)}
SETS = 100


def plan_of(axes):
    return TensorPlan(tuple(Orientation(n, a, OFFSETS.get(n), 2e-5 if n in OFFSETS else 0.0) for n, a in axes),
                      part="bracket", mass=BRACKET.mass, mass_std=1e-4)


def one_set(plan, seed):
    """The results of a set whose true offsets and mass differ from the plan's by their stated 1σ."""
    rng = np.random.default_rng(seed)
    true_plan = replace(plan, orientations=tuple(
        replace(o, offset=tuple(np.add(o.offset, rng.normal(0.0, o.offset_std, 3)).tolist())) if o.offset else o
        for o in plan.orientations))
    body = RigidBody(BRACKET.tensor, BRACKET.mass + rng.normal(0.0, plan.mass_std))
    sets = simulate_set(body, RIG, true_plan, seed=seed)
    results = [[identify(t, RIG) for t in traces] for traces in sets]
    return sets, results


def main():
    truth = TS.entries_of(BRACKET.tensor)
    lam, vec = np.linalg.eigh(np.array(BRACKET.tensor))
    pooled = [0, 0]
    for label, axes in (("default six", TS.DEFAULT_AXES), ("nine", TS.NINE_AXES)):
        plan = plan_of(axes)
        within = total = axes_in = flagged = 0
        worst = 0.0
        for seed in range(1, SETS + 1):
            _, results = one_set(plan, seed)
            r = TS.solve_results(plan, results, RIG)
            z = (TS.entries_of(r.tensor) - truth) / np.sqrt(np.diag(r.cov))
            within += int(np.sum(np.abs(z) <= 2.0))
            total += z.size
            worst = max(worst, float(np.max(np.abs(z))))
            flagged += bool(r.flags)
            for k in range(3):
                angle = np.degrees(np.arccos(min(1.0, abs(float(np.array(r.principal_axes[k]) @ vec[:, k])))))
                axes_in += angle <= r.principal_axes_U_deg[k]
        pooled[0] += within
        pooled[1] += total
        print(f"{label:12} {SETS} sets: components within 2σ {100 * within / total:.1f} % ({within}/{total}, goal 93–97 %),"
              f" largest |z| {worst:.2f}; principal axes within their stated angle {100 * axes_in / (3 * SETS):.1f} %;"
              f" sets flagged {flagged}")
    print(f"both plans: components within 2σ {100 * pooled[0] / pooled[1]:.1f} % ({pooled[0]}/{pooled[1]})")
    # the wait after the last release: its identification, then the tensor of the set
    plan = plan_of(TS.DEFAULT_AXES)
    _, results = one_set(plan, 99)
    for duration, rate in ((12.0, 100.0), (30.0, 200.0)):
        times, solve_times = [], []
        for run in range(5):
            last = simulate_set(BRACKET, RIG, plan, seed=100 + run, duration=duration, rate=rate)[-1][-1]
            t0 = time.perf_counter()
            results[-1] = [identify(last, RIG)]
            t1 = time.perf_counter()
            TS.solve_results(plan, results, RIG)
            t2 = time.perf_counter()
            times.append(t2 - t0)
            solve_times.append(t2 - t1)
        print(f"after the last release ({duration:g} s at {rate:g} Hz): identification + tensor "
              f"{statistics.median(times):.3f} s, median of 5 (the tensor alone, {TS.MONTE_CARLO_DRAWS} Monte Carlo "
              f"draws: {statistics.median(solve_times):.3f} s); goal ≤ 0.5 s")

if __name__ == "__main__":
    import os
    import sys
    sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    main()
