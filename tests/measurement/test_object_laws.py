"""A restoring law is kept only where it is a property of the object.

Within one record: a law that moves ω_n must be determined by the record
(a slow sensor line buys a cubic spring barely told from zero), and a law
whose model's halves disagree is still kept where they disagree far more
without it, and a law the loop did not add is added where the halves demand it. Across the releases of one object: its value keeps one sign
and a consistent size, or it is withdrawn from every release that kept it.
"""

from __future__ import annotations

import datetime as dt
import functools
import math

import numpy as np
import pytest

from measurement import Pendulum, Rig, Trace, identify, simulate_trace
from measurement.fit import fit_model
from measurement.identification import rivals
from measurement.identification.discovery import Move
from measurement.identification.preparation import Prepared
from measurement.model import Model
from measurement.object_laws import LawAcross
from measurement.result import SegmentCheck
from measurement.rig import CalibrationRecord


def test_a_law_that_changes_sign_between_releases_is_not_one_of_the_object():
    # the front wheel on a torsion rod: k3/J fitted to three releases, +818, +3220 and −440
    wheel = LawAcross("cubic_stiffness", "k3_per_J", (818.0, 3220.0, -440.0), (160.0, 350.0, 100.0), (0, 1, 2))
    assert not wheel.stable and "not a law of the object" in wheel.describe()
    # the calibration rod: softening in all five, within a factor 1.4
    rod = LawAcross("cubic_stiffness", "k3_per_J", (-10.8, -9.5, -7.8, -9.7, -7.9), (0.6, 0.4, 0.3, 0.5, 0.3),
                    (0, 1, 2, 3, 4))
    assert rod.stable and rod.everywhere
    # one sign but sizes a factor 10 apart: not one law either
    assert not LawAcross("cubic_stiffness", "k3_per_J", (5.0, 50.0), (1.0, 1.0), (0, 1)).stable
    # values not told from zero say nothing against it, but it is not the object's law in every release
    loose = LawAcross("cubic_stiffness", "k3_per_J", (5.0, -1.0, None), (1.0, 2.0, None), (0,))
    assert loose.stable and not loose.everywhere


def _hardening(seed: int) -> tuple[Trace, Rig, float]:
    # the simulated k is the spring's small-swing stiffness: a calibration read at zero amplitude
    rig = Rig(kind="torsion", stiffness=0.3651, calibration=CalibrationRecord(dt.date(2026, 1, 5), amplitude=0.0))
    J = 0.0125
    spring = Pendulum(rig, J, {"viscous": {"c_per_J": 0.1}, "cubic_stiffness": {"k3": 1.5 * 0.3651}})
    return simulate_trace(spring, theta0=math.radians(5), duration=30.0, rate=200.0, noise_std=2e-4,
                          quantisation_bits=17, seed=seed), rig, J


def test_a_hardening_torsion_spring_is_found_and_kept():
    trace, rig, J = _hardening(seed=1)
    r = identify(trace, rig)
    assert "cubic_stiffness" in r.added_effects
    assert r.J is not None and abs(r.J / J - 1) < 2e-3
    k3 = r.stiffness["cubic_stiffness"]["k3"]
    assert k3.value is not None and k3.std is not None
    assert abs(k3.value - 1.5 * 0.3651) < 4 * k3.std
    # the measurand is the calibration's amplitude's, here the small-swing limit; the swing's frequency at its
    # largest amplitude is beside it
    # (3/8 · 1.5 · (5°)² = +0.43 % by the describing function)
    line = next(s for s in r.structure if "small-swing limit" in s)
    assert "+0.4" in line


def test_a_slow_sensor_line_and_drift_buy_no_amplitude_law():
    rig = Rig(kind="torsion", stiffness=11.67)
    J = 0.27
    rod = Pendulum(rig, J, {"viscous": {"c_per_J": 0.1}})
    clean = simulate_trace(rod, theta0=math.radians(5), duration=30.0, rate=200.0, noise_std=1e-4, seed=2)
    rng = np.random.default_rng(2)
    # a 0.2 Hz line in the sensor, 3.4 % of the release angle, and a drifting zero
    line = 3e-3 * np.sin(2 * math.pi * 0.2 * clean.t + rng.uniform(0, 2 * math.pi)) + 2e-5 * clean.t
    r = identify(Trace(clean.t, clean.angle + line, source="slow line"), rig)
    assert "cubic_stiffness" not in r.effects
    assert r.J is not None and r.J_u is not None and abs(r.J - J) < 2 * r.J_u
    # where the loop added it, the report says why it went, and its ω_n is in u
    assert r.omega_n_std_model is not None
    for c in r.model_form.competitors:
        if c.change.startswith("cubic_stiffness"):
            assert "does not determine" in c.change and abs(c.delta) <= r.omega_n_std_model


@pytest.mark.parametrize("part", ["rod_torsional_first_5"])  # the front wheel's releases: test_bicycle_sets.py
def test_a_rate_record_and_its_integrated_angle_give_one_omega_n(part):
    from pathlib import Path

    from service.sources.dispatch import load_source
    from service.sources.files import read_rig

    data = Path(__file__).resolve().parents[2] / "data"
    rig = read_rig(data / f"bicycle_{part}_rig.toml")
    rate = identify(load_source(data / f"bicycle_{part}_rate.csv"), rig)
    angle = identify(load_source(data / f"bicycle_{part}.csv"), rig)
    assert rate.measures == "rate" and rate.offset.unit == "rad/s" and angle.measures == "angle"
    # the gyro's bias, about 1 °/s, is the rate's fitted zero
    assert rate.offset.value is not None and 0.002 < abs(rate.offset.value) < 0.05
    assert rate.omega_n_u is not None and angle.omega_n_u is not None
    assert abs(rate.omega_n - angle.omega_n) <= 2 * math.hypot(rate.omega_n_u, angle.omega_n_u)


@functools.cache
def _spring_fits():
    """The hardening spring's declared model (viscous) and the model with the cubic spring, fitted to one record."""
    trace, rig, _ = _hardening(seed=3)
    noise = 2e-4
    base = fit_model(Model.from_names(rig, ["viscous"]), trace.t, trace.angle, noise)
    final = fit_model(Model.from_names(rig, ["viscous", "cubic_stiffness"]), trace.t, trace.angle, noise, previous=base)
    move = Move("cubic_stiffness", final.value("omega_n") - base.value("omega_n"), final.stdev("omega_n"), base)
    prep = Prepared(trace.t, trace.angle, noise, 0, trace.t.size, release_detected=False, stopped=False, stuck=False,
                    outliers=np.array([], dtype=int))
    return rig, prep, base, final, move


def _halves(z: float) -> SegmentCheck:
    return SegmentCheck(15.0, (1.0, 1.0), (1e-4, 1e-4), z, math.erfc(z / math.sqrt(2)), 0.0)


@pytest.mark.parametrize(("z_without", "kept"), [(40.0, True), (39.6, False)])
def test_a_restoring_law_is_kept_where_its_halves_disagree_four_times_less_than_without_it(monkeypatch, z_without,
                                                                                           kept):
    # the rule: halves that disagree keep a restoring law where the model without it disagrees at least
    # 1/EXPLAINED_SHARE = 4 times as much (z of its halves); the halves' z is set, the fits are real
    rig, prep, base, final, move = _spring_fits()
    assert move.moved and rivals.undetermined_law(final, ["cubic_stiffness"]) is None  # the 3σ rule passes it
    z_with = 10.0
    monkeypatch.setattr(rivals, "check_segments", lambda fit, sigma: _halves(
        z_with if "cubic_stiffness" in fit.model.effect_names else z_without))
    fit, withdrawn, _ = rivals.hold_across(final, base, [move], prep, rig, None)
    if kept:  # 10 ≤ 40/4: the law explained the halves' disagreement
        assert fit is final and withdrawn is None
    else:  # 10 > 39.6/4: it did not explain enough; withdrawn, its ω_n a rival carried whole
        assert fit.model.effect_names == ("viscous",) and withdrawn is not None
        assert withdrawn.effects == ("cubic_stiffness",) and withdrawn.undetermined is None
        assert withdrawn.omega_n == final.value("omega_n")
        assert withdrawn.segments is not None and withdrawn.segments.z == z_with


@pytest.mark.parametrize(("z_without", "added"), [(40.0, True), (39.6, False)])
def test_a_restoring_law_the_halves_demand_is_added_where_bic_did_not(monkeypatch, z_without, added):
    # the converse rule: the kept model's halves disagree, and the law brings their z down to
    # EXPLAINED_SHARE of it or less; the halves' z is set, the fits are real
    rig, prep, base, final, _ = _spring_fits()
    monkeypatch.setattr(rivals, "check_segments", lambda fit, sigma: _halves(
        10.0 if "cubic_stiffness" in fit.model.effect_names else z_without))
    fit, demanded, _ = rivals.demanded_law(base, prep, rig, None)
    if added:
        assert demanded is not None and fit.model.effect_names == ("viscous", "cubic_stiffness")
        step, move = demanded
        assert step.chosen == move.effect == "cubic_stiffness" and "halves demand" in step.reason
        assert move.start is base and abs(fit.value("omega_n") - final.value("omega_n")) < final.stdev("omega_n")
    else:
        assert demanded is None and fit is base
    # never a law the caller did not allow
    assert rivals.demanded_law(base, prep, rig, None, allowed=("quadratic",))[1] is None


def test_the_rod_read_as_angle_keeps_the_softening_spring_its_rate_record_keeps():
    # its declared model's halves disagree (z 23); with the rod's softening spring they agree (z 2.5)
    # while BIC, each model under its own AR noise model, rises: the halves add it
    from pathlib import Path

    from service.sources.dispatch import load_source
    from service.sources.files import read_rig

    data = Path(__file__).resolve().parents[2] / "data"
    rig = read_rig(data / "bicycle_rod_torsional_first_3_rig.toml")
    angle = identify(load_source(data / "bicycle_rod_torsional_first_3.csv"), rig)
    rate = identify(load_source(data / "bicycle_rod_torsional_first_3_rate.csv"), rig)
    assert "cubic_stiffness" in angle.added_effects and "cubic_stiffness" in rate.added_effects
    assert any("halves demand" in st.reason for st in angle.steps)
    k3 = angle.stiffness["cubic_stiffness"]["k3"]
    assert k3.value is not None and k3.value < 0  # softening, as in every release of the rod
    assert angle.omega_n_u is not None and rate.omega_n_u is not None
    assert abs(angle.omega_n - rate.omega_n) <= 2 * math.hypot(angle.omega_n_u, rate.omega_n_u)
