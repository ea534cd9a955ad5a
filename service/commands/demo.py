"""`moi demo`: one simulated measurement end to end, printed (what `make demo` runs)."""

from __future__ import annotations

import argparse

from measurement import Pendulum, Rig, identify, simulate_trace

HELP = "one simulated push-button measurement, end to end"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--seed", type=int, default=1, help="noise seed")


def run(args: argparse.Namespace) -> int:
    rig = Rig(kind="torsion", stiffness=0.3651, tare_inertia=4.5043e-3, declared=("viscous",))
    truth = Pendulum(rig, 0.0125, {"viscous": {"c": 1.5e-4}, "coulomb": {"Tc": 1.2e-4}})
    print(f"simulated torsion rig: k = {rig.stiffness} N·m/rad, true J = {truth.inertia} kg·m², "
          f"effects {dict(truth.effects)} (declared: viscous only)")
    trace = simulate_trace(truth, theta0=0.25, duration=30, rate=200, noise_std=1e-4, quantisation_bits=17,
                           pre_trigger=0.5, seed=args.seed)
    result = identify(trace, rig)
    print(result.report())
    print(f"true J {truth.inertia} kg·m² → error {100 * (result.J / truth.inertia - 1):+.4f} %")
    return 0
