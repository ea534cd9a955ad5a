"""The two measured wood-pendulum sessions: what the loop finds in each, as tracked and with the camera's view
measured from the two markers, and that what still separates them is flagged."""

import json
import math
from pathlib import Path

import pytest

from measurement import identify, parse_trace_csv
from measurement.errors import ResultSchemaError
from measurement.reports import result_report
from measurement.result import SCHEMA_VERSION, IdentificationResult
from measurement.rig import Rig
from measurement.vision.marker_pair import measure_view, pair_trace, parse_marker_csv

DATA = Path(__file__).resolve().parents[2] / "data"


@pytest.fixture(scope="module")
def runs():
    rig = Rig(kind="compound", declared=("viscous",))
    out = {}
    for name in ("wood_pendulum_60deg.csv", "wood_pendulum_120deg.csv"):
        with open(DATA / name, encoding="utf-8") as fh:
            out[name] = identify(parse_trace_csv(fh, source=name), rig)
    return out


@pytest.fixture(scope="module")
def calibrated():
    """The same releases from their markers' positions, the camera's view measured and removed."""
    rig = Rig(kind="compound", declared=("viscous",), sensor_calibrated=True)
    out = {}
    for name in ("wood_markers_60deg.csv", "wood_markers_120deg.csv"):
        with open(DATA / name, encoding="utf-8") as fh:
            track = parse_marker_csv(fh, source=name)
        out[name] = identify(pair_trace(track, measure_view(track.a, track.b)), rig)
    return out


def _withdrawn_presliding(r):
    """The loop chose pre-sliding friction, but the ω_n it moved does not hold across the record:
    withdrawn to the Coulomb friction it refines, its ω_n a rival in the uncertainty."""
    assert "dahl" in [s.chosen for s in r.steps]
    assert "dahl" not in r.effects and "coulomb" in r.effects and "model_ambiguous" in r.flags
    rival = next(c for c in r.model_form.competitors if c.change.startswith("dahl kept"))
    assert abs(rival.delta) <= r.omega_n_u


def test_small_swings_of_the_60deg_session_ask_for_presliding_friction_that_does_not_hold(runs):
    r = runs["wood_pendulum_60deg.csv"]
    _withdrawn_presliding(r)
    assert r.residual_rms < r.baseline.residual_rms
    # the tracked angle keeps the camera's oblique view, which no constant sensor scale explains
    # (a fitted view differs between the halves of the record): the halves disagree on ω_n, and
    # the result says so and carries their scatter in its uncertainty (well above the fit's σ, which
    # takes in some of the same structure: it is never below what the record's own residual says)
    assert "view" not in r.effects and any("view does not hold across the record" in s.reason for s in r.steps)
    assert "halves_disagree" in r.flags and r.omega_n_std_model > 3 * r.omega_n_std


def test_both_sessions_find_dry_friction(runs):
    for r in runs.values():
        assert {"coulomb", "dahl"} & set(r.effects)


def test_oblique_view_explains_the_unequal_half_swings_of_the_120deg_session(runs):
    r = runs["wood_pendulum_120deg.csv"]
    assert "view" in r.added_effects
    assert "unmodeled_residual" not in r.flags
    assert abs(r.diagnostics.asymmetry_t) < 4


def test_sessions_that_disagree_on_omega_n_say_what_is_left(runs):
    r60, r120 = runs["wood_pendulum_60deg.csv"], runs["wood_pendulum_120deg.csv"]
    # as tracked, the sessions disagree (the 60° one keeps the camera's oblique view in its angle): the rule
    # below has something to hold, and each session names what it leaves
    assert not _agree(r60, r120)
    _name_what_is_left(r60, r120, {"unmodeled_residual": "left unexplained", "sensor_scale_fitted": "scale was fitted"})


def _agree(r60, r120) -> bool:
    """The two sessions give the same ω_n, within 0.1 % and 3 σ of their fits, with the same model."""
    gap = abs(r60.omega_n - r120.omega_n)
    combined = sum(r.omega_n_std**2 + (r.omega_n_std_calibration or 0.0) ** 2 for r in (r60, r120)) ** 0.5
    return gap < 1e-3 * r60.omega_n and gap < 3 * combined and set(r60.effects) == set(r120.effects)


def _name_what_is_left(r60, r120, named):
    gap = abs(r60.omega_n - r120.omega_n)
    if not _agree(r60, r120):  # the product's rule: agreement, or a flag naming what is left
        for r in (r60, r120):
            raised = [f for f in named if f in r.flags]
            assert raised
            assert all(any(named[f] in line for line in r.structure) for f in raised)
    return gap / r60.omega_n


def test_the_camera_view_measured_from_the_markers_takes_the_place_of_a_fitted_scale(runs, calibrated):
    c60, c120 = calibrated.values()
    for r in (c60, c120):
        assert r.sensor_calibrated
        assert not {"gain", "view"} & set(r.effects) and "sensor_scale_fitted" not in r.flags
        assert r.acquisition["view"]["samples"] > 1900
        assert 0 < r.omega_n_std_calibration < 0.01  # the view's own 1σ, carried into ω_n
    # the 120° session's oblique view, measured from the markers, is the one its swing asked for
    assert 0.01 < c120.acquisition["view"]["shear"] < 0.04
    # as tracked and with the view measured, the two sessions agree within their stated uncertainty
    for a, b in (runs.values(), (c60, c120)):
        assert abs(a.omega_n - b.omega_n) < 2 * (a.omega_n_u**2 + b.omega_n_u**2) ** 0.5
    _name_what_is_left(c60, c120, {"camera_perspective": "more than oblique", "halves_disagree": "halves"})


def test_with_the_camera_calibrated_each_session_keeps_its_friction(calibrated):
    c60, c120 = calibrated.values()
    _withdrawn_presliding(c60)
    assert {"coulomb", "quadratic"} <= set(c120.added_effects)


def test_a_result_reads_back_as_typed_fields_and_writes_the_same_json(runs, calibrated):
    # the tracked sessions (a withdrawn rival, a fitted view) and the marker pairs (a measured view, perspective)
    for r in [*runs.values(), *calibrated.values()]:
        text = r.to_json()
        back = IdentificationResult.from_dict(json.loads(text))
        assert back.to_json() == text
        assert back.model_form == r.model_form and back.diagnostics == r.diagnostics and back.steps == r.steps
        assert back.uncertainty_budget.keys() == r.uncertainty_budget.keys()
        assert result_report(back) == result_report(r)
        # the warnings among the flags, graded by the flag table (a perspective the view does not explain,
        # a sensor scale fitted from the swing); the rest is information
        assert json.loads(text)["warnings"] == [f for f in r.flags if f in ("camera_perspective", "sensor_scale_fitted")]
    older = json.loads(text) | {"schema": 3}
    with pytest.raises(ResultSchemaError, match=f"schema 3; expected schema {SCHEMA_VERSION}"):
        IdentificationResult.from_dict(older)



def test_a_release_whose_rivals_disagree_states_them_in_its_answer(calibrated):
    # the 60° release's model does not hold across its record and a withdrawn rival reads 0.5 % lower:
    # its u reaches the rival and the other session's value, and the report's answer says so on its own line
    c60, c120 = calibrated.values()
    assert {"halves_disagree", "model_ambiguous"} <= set(c60.flags)
    for rival in c60.model_form.competitors:
        assert abs(rival.delta) <= 2 * c60.omega_n_u
    assert abs(c60.omega_n - c120.omega_n) <= 2 * math.hypot(c60.omega_n_u, c120.omega_n_u)
    line = next(x for x in result_report(c60).splitlines() if x.strip().startswith("ω_n ± u"))
    assert f"± {c60.omega_n_u:.2g} rad/s" in line
