"""Dahl (pre-sliding) friction: integrated exactly, found where the data hold it, never added to clean data."""

import math

import numpy as np
import pytest

from measurement import identify
from measurement.effects import EFFECTS, candidate_effects, resolve_effects
from measurement.errors import UnknownEffectError
from measurement.integrator import Dynamics
from measurement.rig import Rig
from measurement.simulate import Pendulum, simulate_trace

# a compound pendulum like the wooden one of data/: ω_n = 5.8 rad/s
RIG = Rig(kind="compound", mass=1.0, com_distance=1.0, g=9.81, declared=("viscous",))
J = 9.81 / 5.8**2


def _swing(kind, names, values, theta_c_step=1.0):
    rig = Rig(kind=kind, stiffness=1.0) if kind == "torsion" else RIG
    t = np.linspace(0.0, 30.0, 3001)
    effects = resolve_effects(names, rig)
    x, _ = Dynamics(kind, effects, values).integrate(t, 1.0, 0.0, 5.8, 0.05 / 5.8 / 3 * theta_c_step)
    return t, x


@pytest.mark.parametrize("kind", ["torsion", "compound"])
@pytest.mark.parametrize("tc", [0.1, 1.0])
def test_zero_presliding_angle_is_coulomb_friction_exactly(kind, tc):
    _, coulomb = _swing(kind, ("viscous", "coulomb"), [[0.05], [tc]])
    _, dahl = _swing(kind, ("viscous", "dahl"), [[0.05], [tc, 0.0]])
    assert np.array_equal(coulomb, dahl)
    if tc == 1.0:  # strong enough to hold the pendulum: it sticks, as dry friction does
        assert np.all(dahl[-100:] == dahl[-1])


@pytest.mark.parametrize("kind", ["torsion", "compound"])
def test_dahl_tends_to_coulomb_and_is_integrated_accurately(kind):
    _, coulomb = _swing(kind, ("viscous", "coulomb"), [[0.05], [0.1]])
    gaps = []
    for theta_c in (1e-6, 1e-4, 1e-2):
        _, x = _swing(kind, ("viscous", "dahl"), [[0.05], [0.1, theta_c]])
        _, fine = _swing(kind, ("viscous", "dahl"), [[0.05], [0.1, theta_c]], theta_c_step=1 / 8)
        assert np.max(np.abs(x - fine)) < 3e-5  # the step does not matter
        gaps.append(np.max(np.abs(x - coulomb)))
    # the difference from dry friction shrinks with θ_c (as its square root: the
    # impulse of the turn-over at each reversal)
    assert gaps[0] < gaps[1] < gaps[2] and gaps[0] < 1e-3


def test_presliding_spring_sets_the_frequency_of_small_swings():
    t, x = _swing("compound", ("dahl",), [[0.6, 0.05]])
    centre = np.median(x[-300:])  # dry friction leaves the pendulum off zero
    y = x - centre
    up = np.where((y[:-1] < 0) & (y[1:] >= 0))[0]
    periods = np.diff(t[up] - y[up] * (t[up + 1] - t[up]) / (y[up + 1] - y[up]))
    # the swings decay into the pre-sliding range (here ≈0.01 rad ≪ θ_c), where
    # the friction is a spring T_c/θ_c beside gravity's ω_n²
    assert np.max(np.abs(x[-300:] - centre)) < 0.3 * 0.05
    expected = 2 * math.pi / math.sqrt(5.8**2 + 0.6 / 0.05)
    assert abs(periods[-1] - expected) < 0.01 * expected
    assert periods[0] > 1.15 * expected


def test_dahl_and_coulomb_exclude_each_other():
    with pytest.raises(UnknownEffectError, match="exclude each other"):
        resolve_effects(("coulomb", "dahl"), RIG)


def test_dahl_is_offered_only_as_a_refinement_of_dry_friction():
    assert "dahl" not in [e.name for e in candidate_effects(RIG, ("viscous",))]
    offered = [e.name for e in candidate_effects(RIG, ("viscous", "coulomb"))]
    assert "dahl" in offered
    # once in the model, the friction it contains is not offered again
    assert "coulomb" not in [e.name for e in candidate_effects(RIG, ("viscous", "dahl"))]


@pytest.mark.parametrize("seed", [1, 2])
@pytest.mark.parametrize(("tc", "theta_c"), [(0.19, 0.08), (0.10, 0.02)])
def test_loop_finds_presliding_friction_and_its_angle(seed, tc, theta_c):
    truth = {"viscous": {"c_per_J": 0.1}, "dahl": {"Tc_per_J": tc, "theta_c": theta_c}}
    trace = simulate_trace(Pendulum(RIG, J, truth), theta0=1.0, duration=28, rate=60, noise_std=0.005, seed=seed)
    r = identify(trace, RIG)
    assert r.added_effects == ("dahl",), r.steps
    d = r.damping["dahl"]
    assert d["theta_c"].value is not None and d["theta_c"].std is not None
    assert d["Tc_per_J"].value is not None and d["Tc_per_J"].std is not None
    assert abs(d["theta_c"].value - theta_c) < 4 * d["theta_c"].std
    assert abs(d["Tc_per_J"].value - tc) < 4 * d["Tc_per_J"].std
    assert abs(r.omega_n - 5.8) < 4 * r.omega_n_std
    assert "unmodeled_residual" not in r.flags
    # the refinement is said: coulomb was added first, then replaced by dahl
    chosen = [s.chosen for s in r.steps if s.chosen]
    assert chosen == ["coulomb", "dahl"]


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_dry_friction_without_presliding_stays_coulomb(seed):
    truth = {"viscous": {"c_per_J": 0.1}, "coulomb": {"Tc_per_J": 0.19}}
    trace = simulate_trace(Pendulum(RIG, J, truth), theta0=1.0, duration=28, rate=60, noise_std=0.005, seed=seed)
    r = identify(trace, RIG)
    assert r.added_effects == ("coulomb",)
    tried = {name for s in r.steps for name in s.candidates}
    assert "dahl" in tried  # offered, and refused


def test_a_presliding_angle_below_a_microradian_holds_like_dry_friction():
    # stiffer than any record resolves: near rest it would chatter through millions of reversals
    _, x = _swing("compound", ("viscous", "dahl"), [[0.05], [1.0, 1e-9]])
    _, coulomb = _swing("compound", ("viscous", "coulomb"), [[0.05], [1.0]])
    assert np.all(x[-100:] == x[-1])
    assert abs(x[-1] - coulomb[-1]) < 1e-4


def test_dry_friction_declared_as_dahl_reports_cleanly():
    """A coulomb record fitted with dahl declared: θ_c near 0, its spring's stiffness huge or undefined, the JSON still strict."""
    import json

    from measurement import Options

    rig = Rig(kind="compound", mass=1.0, com_distance=1.0, g=9.81, declared=("viscous", "dahl"))
    truth = {"viscous": {"c_per_J": 0.1}, "coulomb": {"Tc_per_J": 0.19}}
    trace = simulate_trace(Pendulum(rig, J, truth), theta0=1.0, duration=28, rate=60, noise_std=0.005, seed=1)
    r = identify(trace, rig, Options(discover=False))
    theta_c, tc = r.damping["dahl"]["theta_c"], r.damping["dahl"]["Tc_per_J"]
    assert theta_c.value is not None and theta_c.std is not None and tc.value is not None and tc.std is not None
    assert theta_c.value < 3 * theta_c.std + 1e-3
    assert abs(tc.value - 0.19) < 4 * tc.std
    json.dumps(r.to_dict(), allow_nan=False)
    assert EFFECTS["dahl"](rig).physical([0.19, 0.0], 1.0, 5.8)["presliding_stiffness"] is None
