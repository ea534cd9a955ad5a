"""Typed results for the tests of a release's judgement: one identified swing with its measurands and their
uncertainty budgets replaced (what ``measurement.verdict.Reading.from_result`` reads)."""

from __future__ import annotations

import dataclasses
import functools
import math

from measurement import Pendulum, Rig, identify, simulate_trace
from measurement.result import IdentificationResult
from measurement.uncertainty import Budget


@functools.cache
def _swing() -> IdentificationResult:
    rig = Rig(kind="torsion", stiffness=0.3651, stiffness_std=3.4e-4, declared=("viscous",))
    trace = simulate_trace(Pendulum(rig, 0.0125, {"viscous": {"c": 1.5e-4}}), theta0=0.25, duration=5, rate=100,
                           noise_std=1e-4, seed=3)
    return identify(trace, rig)


def judged(values: dict[str, float], u_random: float, u_systematic: float = 0.0, *, flags: tuple[str, ...] = (),
           coverage_factor: float = 2.0, **fields) -> IdentificationResult:
    """A result whose measurands (``values``: J, J_object, J_object_axis → kg·m²) each carry a budget of these
    random and systematic 1σ (kg·m²); the rest of ``fields`` replaced as given (omega_n, window...)."""
    u = math.hypot(u_random, u_systematic)
    budgets = {q: Budget(q, v, "kg·m²", (), (), 0.0, u, u_random, u_systematic, math.inf, coverage_factor,
                         coverage_factor * u) for q, v in values.items()}
    measurands = {q: values.get(q) for q in ("J", "J_object", "J_object_axis")}
    return dataclasses.replace(_swing(), **(measurands | fields), flags=tuple(flags), uncertainty_budget=budgets)
