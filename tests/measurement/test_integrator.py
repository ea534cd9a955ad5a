"""The compiled integrator: one kernel per rig kind, generated from the effect library's terms."""

import numpy as np

from measurement import Rig
from measurement.effect_base import Effect, Parameter
from measurement.effects import EFFECTS
from measurement.integrator import is_compiled
from measurement.model import Model


def test_an_effect_added_to_the_library_is_integrated_by_its_term(tmp_path, monkeypatch):
    monkeypatch.setenv("MOI_CACHE_DIR", str(tmp_path))
    rig = Rig(kind="torsion", stiffness=1.0)

    class ExtraSpring(Effect):  # a linear spring in parallel: ω² = ω_n² + k_per_J
        name = "extra_spring_for_test"
        role = "stiffness"
        parameters = (Parameter("k_per_J", "1/s²", None, None),)
        term = "p0 * x"

    EFFECTS[ExtraSpring.name] = ExtraSpring  # the library lists it
    try:
        assert not is_compiled("torsion")  # a new library: a new kernel, compiled on first use
        t = np.linspace(0.0, 20.0, 2001)
        spring = Model.from_names(rig, ("viscous", ExtraSpring.name))
        x = spring.vector((0.3, 0.0, 2.0), {"viscous": [0.05], ExtraSpring.name: [5.0]})
        theta, _ = spring.true_angle(x, t, 0.005)
        plain = Model.from_names(rig, ("viscous",))
        same = plain.vector((0.3, 0.0, 3.0), {"viscous": [0.05]})
        expected, _ = plain.true_angle(same, t, 0.005)
        assert np.max(np.abs(theta - expected)) < 1e-12
        assert list(tmp_path.glob("moi_kernel_torsion_*.py"))  # generated into the cache directory
        assert is_compiled("torsion")  # and its machine code cached beside it for the next process
    finally:
        EFFECTS.pop(ExtraSpring.name)


def test_a_model_without_an_effect_is_the_kernel_with_that_effect_at_zero():
    rig = Rig(kind="compound", mass=2.0, com_distance=0.3)
    t = np.linspace(0.0, 10.0, 1001)
    full = Model.from_names(rig, ("viscous", "coulomb", "quadratic"))
    x = full.vector((0.5, 0.0, 5.0), {"viscous": [0.02], "coulomb": [0.0], "quadratic": [0.0]})
    small = Model.from_names(rig, ("viscous",))
    y = small.vector((0.5, 0.0, 5.0), {"viscous": [0.02]})
    assert np.array_equal(full.true_angle(x, t, 0.01)[0], small.true_angle(y, t, 0.01)[0])
