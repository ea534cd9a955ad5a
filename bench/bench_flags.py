"""How often each quality flag fires: on the shared real sets, and on simulation with and without its condition.

A flag that fires on every part says nothing, and one that invalidates a good
part teaches the operator to ignore flags. Each flag is graded
(``measurement.flags.GRADES``): a warning may move ω_n or J beyond the stated
u, information describes the record or its residual. This bench counts, per
flag and grade:

* the real sets (bench_precision's: data/ and, when ../shared is there, the
  racquet's phone-gyro recording): each release identified alone, and each
  set's joint identification;
* simulated torsion-rig records: clean (the declared model is the truth),
  and with one condition each (dry friction the loop may not learn, glitch
  samples, a sensor read 3 % off its scale and not calibrated, a restoring
  law softer than the rig's), a few seeds each.

Goal: on the real sets most answers carry no warning; a clean simulated record none at all.

    .venv/bin/python bench/bench_flags.py            # real sets and simulation (several minutes)
    .venv/bin/python bench/bench_flags.py --sim      # simulation only
"""

from __future__ import annotations

import sys
from collections import Counter
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "bench"))

import bench_precision as precision  # noqa: E402

from measurement import Options, Pendulum, Rig, Trace, identify, simulate_trace  # noqa: E402
from measurement import flags as F  # noqa: E402
from measurement.errors import MeasurementError  # noqa: E402
from measurement.joint import identify_releases  # noqa: E402

RIG = Rig(kind="torsion", stiffness=0.3651, declared=("viscous",))
#: a compound rig swung wide, where the angle's scale reaches ω_n through sin θ
COMPOUND = Rig(kind="compound", mass=1.5, com_distance=0.25, declared=("viscous",))
SEEDS = (1, 2, 3)


def _glitches(trace: Trace, seed: int) -> Trace:
    y = trace.angle.copy()
    rng = np.random.default_rng(seed)
    y[rng.choice(y.size, 6, replace=False)] += 0.05
    return Trace(trace.t, y, source=trace.source)


def _scaled(trace: Trace, _seed: int) -> Trace:
    return Trace(trace.t, 1.03 * trace.angle, source=trace.source)


#: condition → (effects simulated, what is done to the record, identification options, rig, J, release angle)
CONDITIONS = {
    "clean": ({}, None, Options(), RIG, 0.0125, 0.3),
    "clean, compound": ({}, None, Options(), COMPOUND, 0.12, 0.8),
    "dry friction, not learnt": ({"coulomb": {"Tc": 4e-4}}, None, Options(discover=False), RIG, 0.0125, 0.3),
    "glitch samples": ({}, _glitches, Options(), RIG, 0.0125, 0.3),
    "compound, sensor 3 % off": ({}, _scaled, Options(), COMPOUND, 0.12, 0.8),
    "softer law, not learnt": ({"cubic_stiffness": {"k3": -0.05}}, None, Options(discover=False), RIG, 0.0125, 0.3),
}


def simulated(condition: str, seed: int) -> tuple[tuple[str, ...], float]:
    """(the flags of one simulated record, |J − J_true| over the stated J_u)."""
    effects, spoil, options, rig, inertia, theta0 = CONDITIONS[condition]
    damping = 1.5e-4 if rig.kind == "torsion" else 1.0e-3
    truth = Pendulum(rig, inertia, {"viscous": {"c": damping}, **effects})
    trace = simulate_trace(truth, theta0=theta0, duration=20.0, rate=100.0, noise_std=1e-4, seed=seed)
    if spoil is not None:
        trace = spoil(trace, seed)
    try:
        r = identify(trace, rig, options)
    except MeasurementError as exc:
        return (f"error: {exc}",), float("nan")
    z = abs(r.J - inertia) / r.J_u if r.J is not None and r.J_u else float("nan")
    return r.flags, z


def real() -> tuple[Counter[str], int, int, Counter[str], int, int]:
    """(flag counts, answers, answers with a warning) of the releases alone, then of the joint fits."""
    alone: Counter[str] = Counter()
    joint: Counter[str] = Counter()
    n_alone = n_joint = warned_alone = warned_joint = 0
    for _, releases in precision.SETS:
        for trace_file, rig_file in releases:
            try:
                flags = identify(precision.load_trace(trace_file), precision.load_rig(rig_file)).flags
            except MeasurementError:
                continue
            alone.update(flags)
            n_alone += 1
            warned_alone += bool(F.warnings(flags))
        try:
            j = identify_releases([precision.load_trace(f) for f, _ in releases], precision.load_rig(releases[0][1]))
        except MeasurementError:
            continue
        joint.update(j.flags)
        n_joint += 1
        warned_joint += bool(F.warnings(j.flags))
    return alone, n_alone, warned_alone, joint, n_joint, warned_joint


def main() -> None:
    sim_only = "--sim" in sys.argv
    runs = {c: [simulated(c, s) for s in SEEDS] for c in CONDITIONS}
    counts = {c: Counter(f for flags, _ in runs[c] for f in flags) for c in CONDITIONS}
    columns = list(CONDITIONS)
    print(f"simulated records, {len(SEEDS)} seeds per condition: how many carry each flag, and the worst |J − J_true|/J_u")
    print("| flag | grade | " + " | ".join(columns) + " |")
    print("|---|---|" + "---:|" * len(columns))
    fired = sorted({f for c in counts.values() for f in c}, key=lambda f: (F.grade(f), f))
    for f in fired:
        print(f"| {f} | {F.grade(f)} | " + " | ".join(str(counts[c][f]) for c in columns) + " |")
    print("| worst \\|J − J_true\\|/J_u | | " + " | ".join(f"{max(z for _, z in runs[c]):.2f}" for c in columns) + " |")
    if sim_only:
        return
    alone, n_alone, w_alone, joint, n_joint, w_joint = real()
    print()
    print(f"real sets: {n_alone} releases identified alone, {n_joint} joint identifications")
    print("| flag | grade | releases alone | joint |")
    print("|---|---|---:|---:|")
    for f in sorted(set(alone) | set(joint), key=lambda f: (F.grade(f), -alone[f])):
        print(f"| {f} | {F.grade(f)} | {alone[f]} ({100 * alone[f] / n_alone:.0f} %) | {joint[f]} |")
    print(f"| any warning | | {w_alone} ({100 * w_alone / n_alone:.0f} %) | {w_joint} |")


if __name__ == "__main__":
    main()
