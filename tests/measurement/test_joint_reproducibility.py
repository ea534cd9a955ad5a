"""A part's releases identified with the rig's reproducibility in their u: their joint value, its u and the Birge
ratio are the ones without it (the joint u weighs each release by its own fit and model form; the releases'
scatter speaks for itself), while each release's own budget holds the history's line and its degrees of freedom."""

from __future__ import annotations

import pytest

from measurement import Options, Pendulum, Rig, identify, simulate_trace
from measurement.joint import joint_value
from measurement.reproducibility import Reproducibility
from measurement.verdict import Reading

RIG = Rig(kind="torsion", stiffness=0.3651, stiffness_std=0.3651e-4, declared=("viscous",))
HISTORY = Reproducibility(1e-3, 4.0, 1, 5, "history", True)


def test_the_joint_value_and_its_u_do_not_hold_the_releases_reproducibility_line():
    traces = [simulate_trace(Pendulum(RIG, 0.0125, {"viscous": {"c": 2e-4}}), theta0=0.3, duration=10.0, rate=100.0,
                             noise_std=2e-4, seed=s) for s in (1, 2, 3)]
    alone = [identify(t, RIG, Options()) for t in traces]
    counted = [identify(t, RIG, Options(reproducibility=HISTORY)) for t in traces]
    before, after = joint_value(alone, RIG, "J"), joint_value(counted, RIG, "J")
    assert before is not None and after is not None
    assert after[0] == pytest.approx(before[0], rel=1e-12) and after[1] == pytest.approx(before[1], rel=1e-9)
    assert after[2]["consistency"]["birge_ratio"] == pytest.approx(before[2]["consistency"]["birge_ratio"], rel=1e-9)
    # each release's own budget: the history's line in u, its ν = 4 raising k (Welch–Satterthwaite)
    for r in counted:
        line = next(ln for ln in r.uncertainty_budget["J"].lines if ln.symbol == "omega_n_repro")
        assert line.std == 1e-3 and line.dof == 4.0
        assert (Reading.from_result(r, "J").coverage_factor or 0.0) > 2.5
    assert all(Reading.from_result(r, "J").coverage_factor == 2.0 for r in alone)
