"""The appliance's own releases carry the rig's reproducibility between releases in their u: pooled from the store's
repeat releases since the rig's calibration (a check standard measured a few times), on the simulated rig; before
any history the figure the rig's calibration keeps (and without it the documented default, counted:
tests/cli/test_cli_calibrate_reproducibility.py)."""

from __future__ import annotations

import datetime as dt
import math

import numpy as np
import pytest

from measurement.reproducibility import DEFAULT, calibrated
from measurement.uncertainty import coverage_factor, welch_satterthwaite
from tests.service.conftest import appliance_doc


def _setup(tmp_path):
    """The device's rig calibrated last month, its references' releases showing 0.05 % between releases (ν = 4); a
    check standard (one release a part), a part type of one release and one of three."""
    rig = tmp_path / "rig.toml"
    rig.write_text('[rig]\nkind = "torsion"\nstiffness = 0.3651\n[calibration]\n'
                   f'date = {(dt.date.today() - dt.timedelta(days=30)).isoformat()}\nvalid_days = 365\n'
                   'reproducibility = 0.0005\nreproducibility_dof = 4\n')
    recipes = tmp_path / "recipes"
    recipes.mkdir()
    cs = '[check_standard]\nname = "disc CS-1"\nreference = 0.0125\nreference_U = 2.0e-5\n'
    for n, (name, extra) in enumerate((("rotor", ""), ("cs", cs), ("rotor3", "releases = 3\n")), start=1):
        (recipes / f"{name}.toml").write_text(f'[recipe]\nname = "{name}"\nnumber = {n}\nnominal = 0.0125\n'
                                              f'tolerance_percent = 2.0\n{extra}')
    return rig, recipes


def _release(running, n, **data):
    """Trigger one release (``data``: its part ID and recipe) and return its stored row, with its payload."""
    running.app.command("trigger", "cli", data)
    running.wait_done(n, timeout=60)
    assert running.app.recorder.wait_stored(n, 30)
    stored = running.app.store.get(running.app.recorder.stored[n - 1])
    assert stored is not None and stored.status == "ok", stored
    return stored


def _repro_line(payload):
    lines = {ln["symbol"]: ln for ln in payload["uncertainty_budget"]["J"]["lines"]}
    return lines["omega_n_repro"]


def test_a_release_carries_the_rigs_pooled_reproducibility_once_a_check_standard_was_measured(tmp_path,
                                                                                            appliance_factory):
    rig, recipes = _setup(tmp_path)
    doc = appliance_doc(tmp_path / "state", device={"rig": str(rig)},
                        recipes={"directory": str(recipes), "active": "rotor"})
    running = appliance_factory(doc)
    # before any history: the rig's calibration figure, in u (not the default)
    first = _release(running, 1, recipe="rotor").payload
    assert first["reproducibility"] == calibrated(0.0005, 4.0).to_dict() != DEFAULT.to_dict()
    line = _repro_line(first)
    assert line["stated"] and line["std"] == 0.0005 and line["dof"] == 4 and abs(line["contribution"]) > 0
    assert "rig: its calibration's" in line["note"]
    # the check standard measured three times: one object, three releases, two degrees of freedom
    checks = [_release(running, n, recipe="cs") for n in (2, 3, 4)]
    assert len(running.app.store.check_standards(limit=None)) == 3
    part = _release(running, 5, part_id="R-1", recipe="rotor").payload
    # by hand: the pooled relative within-group sd of the check standard's stored ω_n (one group)
    w = np.array([c.omega_n for c in checks])
    hand = float(np.sqrt(np.sum((w / w.mean() - 1.0) ** 2) / (w.size - 1)))
    repro = part["reproducibility"]  # the history wins over the rig's calibration figure
    assert (repro["source"], repro["counted"], repro["dof"], repro["groups"], repro["releases"]) == \
        ("history", True, 2, 1, 3)
    assert repro["relative"] == pytest.approx(hand, rel=1e-9)
    line = _repro_line(part)
    assert line["std"] == pytest.approx(hand, rel=1e-9) and line["dof"] == 2
    assert abs(line["contribution"]) > 0 and "history: 3 releases of 1 object pooled" in line["note"]
    # in u, with its few degrees of freedom in the budget's (Welch–Satterthwaite)
    budget = part["uncertainty_budget"]["J"]
    assert budget["u"] > abs(line["contribution"]) and budget["dof"] is not None
    assert budget["u_random"] >= abs(line["contribution"])  # a random line: one release's own, not shared
    # the appliance read the store once for this calibration, then kept it with what it stored
    assert running.app.history.reproducibility(running.app.config.rig).relative == pytest.approx(
        _pooled_with(running), rel=1e-12)
    # a part of three releases: each release's u holds the history, the part keeps its joint value (its joint u is
    # the joint identification's: tests/measurement/test_joint_reproducibility.py) and its own k
    releases = [_release(running, n, part_id="R-3", recipe="rotor3").payload for n in (6, 7, 8)]
    assert all(r["reproducibility"]["source"] == "history" for r in releases)
    summary = releases[-1]["part"]
    joint = summary["joint"]
    assert joint is not None and summary["value"] == pytest.approx(0.3651 / joint["omega_n"] ** 2, rel=1e-9)
    # its k: the specification's, or its own releases' Type A (Welch–Satterthwaite, m − 1) where that sets u; never
    # a release's k that its history's line raised
    u_a, u_fit = summary["u_typeA"], summary["u_fit"]
    u_c = math.hypot(max(u_a, u_fit), summary["u_systematic"])
    k = coverage_factor(welch_satterthwaite(u_c, [(u_a, 2)])) if u_a > u_fit else 2.0
    assert summary["uncertainty"]["coverage_factor"] == pytest.approx(k, rel=1e-9)
    assert summary["U"] == pytest.approx(k * summary["u_c"], rel=1e-9)


def _pooled_with(running):
    """The store read anew: what the kept history must equal."""
    from service.sources.repeats import calibrated_since, rig_reproducibility

    r = rig_reproducibility(running.app.store, calibrated_since(running.app.config.rig.calibration))
    assert r.relative is not None
    return r.relative
