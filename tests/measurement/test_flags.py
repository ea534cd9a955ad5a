"""Every quality flag has one meaning (measurement.flags) and one Modbus bit (service.publish.modbus.registers)."""

from measurement import flags as F
from measurement.effects import EFFECTS
from service.publish.modbus import registers as R


def test_every_flag_has_a_description_and_a_bit():
    assert set(F.FLAGS) == set(F.FLAG_BITS), "a flag without a bit, or a bit without a described flag"
    for name, meaning in F.FLAGS.items():
        assert meaning.strip(), name
    bits = list(F.FLAG_BITS.values())
    assert len(bits) == len(set(bits)) and F.FLAG_OTHER_BIT not in bits


def test_every_flag_is_graded_and_the_default_and_example_rules_invalidate_by_warnings_only():
    import tomllib
    from pathlib import Path

    from measurement.verdict import DEFAULT_INVALID_FLAGS

    assert set(F.GRADES) == set(F.FLAGS) and set(F.GRADES.values()) == {F.WARNING, F.INFORMATION}
    # what the residual holds is information: its effect on ω_n is in u (the halves, the rivals)
    for described in (F.UNMODELED_RESIDUAL, F.CORRELATED_RESIDUAL, F.HALVES_DISAGREE, F.MODEL_AMBIGUOUS,
                      F.PARAMETER_AT_BOUND, F.OUTLIERS_REMOVED):
        assert F.grade(described) == F.INFORMATION
    assert F.grade(F.FIT_NOT_CONVERGED) == F.WARNING and F.grade("a flag no table knows") == F.WARNING
    assert set(DEFAULT_INVALID_FLAGS) <= set(F.WARNINGS)
    for recipe in (Path(__file__).resolve().parents[2] / "examples" / "recipes").glob("*.toml"):
        named = tomllib.loads(recipe.read_text(encoding="utf-8")).get("quality", {}).get("invalid_flags", [])
        assert set(named) <= set(F.WARNINGS), (recipe.name, named)
    assert F.warnings(["correlated_residual", "sensor_scale_fitted", "halves_disagree"]) == ("sensor_scale_fitted",)


def test_every_library_effect_has_a_bit():
    assert set(EFFECTS) <= set(R.EFFECT_BITS)
    bits = list(R.EFFECT_BITS.values())
    assert len(bits) == len(set(bits)) and R.EFFECT_OTHER_BIT not in bits


def test_identification_raises_only_described_flags():
    import importlib
    import inspect
    import pkgutil

    from measurement import identification

    src = "".join(inspect.getsource(importlib.import_module(f"measurement.identification.{m.name}"))
                  for m in pkgutil.iter_modules(identification.__path__))
    assert "F.UNMODELED_RESIDUAL" in src  # the package's modules were read
    assert '"unmodeled_residual"' not in src and "flags.append(\"" not in src  # constants from the table only


def test_a_tare_larger_than_J_is_flagged_not_published_silently():
    from measurement import Pendulum, Rig, identify, simulate_trace

    truth = Rig(kind="torsion", stiffness=0.3651, declared=("viscous",))
    trace = simulate_trace(Pendulum(truth, 0.0125, {"viscous": {"c": 1.5e-4}}), theta0=0.2, duration=8, rate=100,
                           noise_std=1e-4, seed=2)
    right = identify(trace, Rig(kind="torsion", stiffness=0.3651, tare_inertia=4.5e-3, declared=("viscous",)))
    wrong = identify(trace, Rig(kind="torsion", stiffness=0.3651, tare_inertia=0.02, declared=("viscous",)))
    assert right.J_object is not None and right.J_object > 0 and F.NEGATIVE_INERTIA not in right.flags
    assert wrong.J_object is not None and wrong.J_object < 0 and F.NEGATIVE_INERTIA in wrong.flags
    assert wrong.J == right.J   # J itself is unaffected: only the subtraction is suspect
