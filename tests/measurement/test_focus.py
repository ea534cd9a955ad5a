"""The headline ω_n is read from the model whose ω_n is the more accurate (measurement.identification.focus)."""

from __future__ import annotations

import math
from pathlib import Path

from measurement import Options, Pendulum, Rig, identify, simulate_trace
from measurement.reports import result_report
from measurement.result import IdentificationResult
from service.sources.dispatch import load_source
from service.sources.files import read_rig

ROOT = Path(__file__).resolve().parents[2]
TORSION = Rig(kind="torsion", stiffness=0.3651, declared=("viscous",))


def test_a_clean_record_reads_omega_n_from_its_declared_model_without_a_choice():
    truth = Pendulum(TORSION, 0.0125, {"viscous": {"c": 1.5e-4}})
    r = identify(simulate_trace(truth, theta0=0.3, duration=20, rate=100, noise_std=1e-4, seed=1), TORSION)
    assert r.added_effects == () and r.omega_n_from == "discovered" and r.omega_n_effects == ("viscous",)
    assert not any("root mean squared error" in s for s in r.structure)


def test_an_effect_that_moves_omega_n_far_beyond_its_variance_gives_the_headline():
    # air drag at a wide swing: the declared model's ω_n is biased far beyond what either model's
    # halves scatter, so the discovered model's ω_n is the more accurate
    truth = Pendulum(TORSION, 0.0125, {"viscous": {"c": 1.5e-4}, "quadratic": {"K": 4e-3}})
    r = identify(simulate_trace(truth, theta0=0.6, duration=20, rate=100, noise_std=1e-4, seed=2), TORSION)
    assert "quadratic" in r.effects and r.omega_n_from == "discovered"
    w_true = math.sqrt(0.3651 / 0.0125)
    assert r.omega_n_u is not None and abs(r.omega_n - w_true) < 2 * r.omega_n_u
    assert any("would be the less accurate" in s for s in r.structure)


def test_a_release_whose_discovered_omega_n_is_less_accurate_reads_the_declared_one_and_keeps_the_rival():
    # the front wheel swung as a compound pendulum, its third release: what the loop adds lowers BIC but
    # widens ω_n's model-form term; the declared model's ω_n lies within what the two models' variances
    # allow of the discovered one's, and its halves scatter less
    trace = load_source(ROOT / "data/bicycle_fwheel_compound_first_3.csv")
    rig = read_rig(ROOT / "data/bicycle_fwheel_compound_first_3_rig.toml")
    focused, plain = identify(trace, rig), identify(trace, rig, Options(focused=False))
    assert focused.effects == plain.effects and focused.added_effects  # discovery unchanged
    assert focused.omega_n_from == "declared" and focused.omega_n_effects == focused.declared_effects
    assert focused.omega_n == focused.baseline.omega_n
    assert focused.omega_n_u is not None and plain.omega_n_u is not None
    assert focused.omega_n_u < plain.omega_n_u
    rival = focused.model_form.competitors[0]
    assert rival.effects == plain.effects and rival.omega_n == plain.omega_n
    assert abs(plain.omega_n - focused.omega_n) <= focused.omega_n_u
    assert any(s.startswith("ω_n is read from the declared model") for s in focused.structure)
    assert "ω_n from     = the declared model" in result_report(focused)
    back = IdentificationResult.from_dict(focused.to_dict())
    assert back.omega_n_from == "declared" and back.omega_n_effects == focused.omega_n_effects


def test_a_fitted_law_read_at_the_records_amplitude_is_one_measurand_with_the_declared_model():
    # a cubic spring's small-swing limit and the declared model's frequency at the swing were two measurands
    # (weighed against each other, releases of one wheel ended 4-5 u apart): on a torsion rig the law is read
    # at the record's own amplitude, where the declared model measures, and the choice is made
    trace = load_source(ROOT / "data/bicycle_fwheel_torsional_first_3.csv")
    r = identify(trace, read_rig(ROOT / "data/bicycle_fwheel_torsional_first_3_rig.toml"))
    assert "cubic_stiffness" in r.added_effects and r.periods is not None and r.omega_n_u is not None
    assert r.omega_n_read_at.basis == "record" and 0.02 < r.omega_n_read_at.amplitude < r.periods.amplitude
    assert r.omega_n_from == "declared" and r.omega_n == r.baseline.omega_n
    assert any("root mean squared error" in s for s in r.structure)
    # the discovered model's ω there is the declared model's within a fraction of u; its limit is far off
    rival = r.model_form.competitors[0]
    assert rival.effects == r.effects and abs(rival.delta) < 0.1 * r.omega_n_u
    assert r.omega_n_read_at.limit is None  # read from the declared model: no law to extrapolate
    assert any(s.startswith("ω_n is the frequency at a swing of") for s in r.structure)
