"""The camera's oblique view (sensor effect ``view``): found where the image is distorted, told from a gain, never added to clean data."""

import numpy as np
import pytest

from measurement import identify
from measurement.effects import EFFECTS, candidate_effects
from measurement.rig import Rig
from measurement.simulate import Pendulum, simulate_trace

RIG = Rig(kind="compound", mass=1.0, com_distance=1.0, g=9.81, declared=("viscous",))
J = 9.81 / 5.8**2


def _trace(sensor, seed, theta0=1.5):
    truth = {"viscous": {"c_per_J": 0.05}, **sensor}
    return simulate_trace(Pendulum(RIG, J, truth), theta0=theta0, duration=28, rate=60, noise_std=0.005, seed=seed)


def test_view_is_the_first_order_affine_image_of_the_direction():
    theta = np.linspace(-2.5, 2.5, 101)
    e1, e2 = 0.03, -0.02
    exact = np.arctan2((1 + e1) * np.sin(theta) + e2 * np.cos(theta), e2 * np.sin(theta) + (1 - e1) * np.cos(theta))
    offset = np.arctan2(e2, 1 - e1)  # the image of the rest direction: taken up by the fitted offset
    first = theta + EFFECTS["view"](RIG).sensor_basis(theta, theta) @ [e1, e2] + offset
    assert np.max(np.abs(first - exact)) < 2 * (e1**2 + e2**2)


@pytest.mark.parametrize("seed", [1, 2])
@pytest.mark.parametrize(("stretch", "shear"), [(0.02, 0.01), (0.0, 0.01)])
def test_loop_finds_an_oblique_view(seed, stretch, shear):
    r = identify(_trace({"view": {"stretch": stretch, "shear": shear}}, seed), RIG)
    assert r.added_effects == ("view",)
    view = r.sensor["view"]
    assert view["shear"].value is not None and view["shear"].std is not None
    assert view["stretch"].value is not None and view["stretch"].std is not None
    assert abs(view["shear"].value - shear) < 4 * view["shear"].std
    assert abs(view["stretch"].value - stretch) < 4 * view["stretch"].std
    assert abs(r.omega_n - 5.8) < 4 * r.omega_n_std


@pytest.mark.parametrize("seed", [1, 2])
def test_a_scale_error_stays_a_gain(seed):
    r = identify(_trace({"gain": {"g": 1.02}}, seed), RIG)
    assert r.added_effects == ("gain",)


@pytest.mark.parametrize("seed", [1, 2])
def test_clean_large_swing_gets_no_sensor_effect(seed):
    r = identify(_trace({}, seed), RIG)
    assert r.added_effects == ()
    assert "view" in {name for s in r.steps for name in s.candidates}


def test_view_is_not_offered_where_it_cannot_be_told_from_the_swing():
    assert "view" not in [e.name for e in candidate_effects(Rig(kind="torsion", stiffness=1.0), ())]
    assert not EFFECTS["view"](RIG).identifiable(0.3)
