"""The guided Type 1 study driven release by release with results stored as the daemon stores them: k of n, the
figures stored with the links to the releases and equal to an independent computation (numpy, scipy's t), every
refusal with its reason, the abort that keeps the releases, the last complete study SPC reads."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from scipy import stats

from service.commands.demo_tensor import recipe_text
from service.parts.gauge_study import StudyDesk, latest_type1, type1_records
from service.parts.recipes import load_recipe
from service.persistence.store import Store

J_REF = 0.0125
T = 2 * 0.02 * J_REF  # ± 2 % of the nominal


def recipe(tmp_path, name="ref", number=1):
    path = tmp_path / f"{name}.toml"
    path.write_text(f'[recipe]\nname = "{name}"\nnumber = {number}\nnominal = {J_REF}\ntolerance_percent = 2.0\n'
                    'display_unit = "g·cm²"\n', encoding="utf-8")
    return load_recipe(path)


@pytest.fixture
def desk(tmp_path):
    store = Store(tmp_path / "state")
    clock = iter(range(1_700_000_000, 1_700_100_000))
    d = StudyDesk(tmp_path / "state", lambda: store, lambda: float(next(clock)))
    yield d, store
    store.close()


def start(d, r, source="web:qe", **data):
    """The start command's data (kg·m²) with the usual values unless given; the desk's answer."""
    data = {"action": "start", "reference": J_REF, "tolerance": T, "count": 25} | data
    return d.act(data, source, recipe=r, part_id="CS-1", busy=False, other=None, block=None)


def release(d, store, r, value, n):
    """One release stored and counted as the daemon's recorder does (the study's release, then the row)."""
    s = d.of(r)
    assert s is not None
    uuid = f"00000000-0000-0000-0000-{n:012d}"
    assert s.release(SimpleNamespace(J=value), uuid)
    store.record(uuid=uuid, status="ok", trigger="test", device_id="d", software_version="t", started_at=n,
                 finished_at=n + 1, result={"J": value, "flags": []}, build_payload=lambda u, q: {"J": value})
    d.released(s)
    return uuid


def test_a_study_counts_each_release_and_stores_figures_equal_to_an_independent_computation(tmp_path, desk):
    d, store = desk
    r = recipe(tmp_path)
    assert start(d, r) == ("done", None, "")
    p = d.progress()
    assert (p["status"], p["done"], p["count"], p["part_id"]) == ("running", 0, 25, "CS-1")
    rng = np.random.default_rng(3)
    values = J_REF + 2e-6 + 4e-6 * rng.standard_normal(25)
    uuids = []
    for k, v in enumerate(values):
        uuids.append(release(d, store, r, float(v), k))
        assert d.progress()["done"] == k + 1
    assert d.progress()["status"] == "complete" and d.of(r) is None
    [rec] = type1_records(store)
    assert rec.status == "complete" and rec.releases == tuple(uuids) and rec.unit == "g·cm²"
    # the stored values are the stored results' J, in order
    assert [store.get(u).J for u in rec.releases] == list(rec.values)
    x = np.array([store.get(u).J for u in rec.releases])
    s = x.std(ddof=1)
    bias = x.mean() - J_REF
    t = bias / (s / math.sqrt(x.size))
    study = rec.study
    assert study is not None
    assert study.cg == pytest.approx(0.2 * T / (6 * s), rel=1e-12)
    assert study.cgk == pytest.approx((0.1 * T - abs(bias)) / (3 * s), rel=1e-12)
    assert study.bias.t == pytest.approx(t, rel=1e-12)
    assert study.bias.p == pytest.approx(2 * stats.t.sf(abs(t), x.size - 1), rel=1e-9)
    assert study.min_tolerance_cg == pytest.approx(1.33 * 6 * s / 0.2, rel=1e-12)
    assert latest_type1(store, "ref") == study and latest_type1(store, "other") is None


def test_a_start_is_refused_with_the_reason(tmp_path, desk):
    d, _ = desk
    r = recipe(tmp_path)
    tensor = tmp_path / "bracket.toml"
    tensor.write_text(recipe_text(1), encoding="utf-8")
    cases = [(start(d, r, tolerance=None), "malformed", "no tolerance"),
             (start(d, r, tolerance=0.0), "malformed", "no tolerance"),
             (start(d, r, reference=""), "malformed", "no reference value"),
             (start(d, r, count=24), "malformed", "at least 25"),
             (start(d, r, count="many"), "malformed", "whole number"),
             (start(d, None), "malformed", "no recipe is active"),
             (start(d, load_recipe(tensor)), "malformed", "tensor recipe"),
             (d.act({"action": "start"}, "web", recipe=r, part_id=None, busy=False, other=None,
                    block="calibration expired on 2021-01-14"), "calibration_due", "calibration expired"),
             (d.act({"action": "start"}, "web", recipe=r, part_id=None, busy=False,
                    other="a tensor set of bracket runs: finish or abort it first", block=None), "busy", "tensor set"),
             (d.act({"action": "start"}, "web", recipe=r, part_id=None, busy=True, other=None, block=None), "busy",
              "a measurement runs"),
             (d.act({"action": "launch"}, "web", recipe=r, part_id=None, busy=False, other=None, block=None),
              "malformed", "unknown study action")]
    for (status, reason, detail), want_reason, words in cases:
        assert (status, reason) == ("refused", want_reason) and words in detail, (reason, detail)
    assert d.progress() is None
    assert start(d, r)[0] == "done"
    status, reason, detail = start(d, r)
    assert (status, reason) == ("refused", "busy") and "runs (0 of 25): abort it first" in detail


def test_an_abort_keeps_the_releases_and_stores_the_study_aborted(tmp_path, desk):
    d, store = desk
    r = recipe(tmp_path)
    assert d.abort("nothing") == ("refused", "nothing_to_abort", "no Type 1 study runs")
    start(d, r)
    kept = [release(d, store, r, J_REF + 1e-6 * k, k) for k in range(3)]
    assert d.act({"action": "abort"}, "web:qe", recipe=r, part_id=None, busy=True, other=None,
                 block=None) == ("done", None, "")
    [rec] = type1_records(store)
    assert rec.status == "aborted" and rec.error == "aborted by web:qe" and rec.releases == tuple(kept)
    assert rec.study is None and store.count() == 3 and d.of(r) is None
    assert latest_type1(store, "ref") is None  # an aborted study gives SPC no figures
    # another recipe selected ends a running study the same way
    start(d, r)
    release(d, store, r, J_REF, 10)
    d.selected(recipe(tmp_path, "other", 2))
    newest = type1_records(store)[0]
    assert newest.status == "aborted" and "another recipe (other)" in str(newest.error) and len(newest.values) == 1


def test_a_release_without_a_value_is_not_counted_and_no_scatter_fails_the_study(tmp_path, desk):
    d, store = desk
    r = recipe(tmp_path)
    start(d, r)
    s = d.of(r)
    assert not s.release(SimpleNamespace(J=None), "no-value") and d.progress()["done"] == 0
    for k in range(25):
        release(d, store, r, 2.0**-7, k)  # a resolution too coarse: every value the same (exact in binary)
    [rec] = type1_records(store)
    assert rec.status == "failed" and "no scatter" in str(rec.error) and len(rec.values) == 25


def test_a_study_a_kill_cut_short_is_stored_as_aborted_at_the_next_start(tmp_path, desk):
    d, store = desk
    r = recipe(tmp_path)
    start(d, r)
    kept = [release(d, store, r, J_REF + 1e-6 * k, k) for k in range(2)]
    assert d.file.path.exists() and type1_records(store) == []  # killed here: nothing stored but the releases
    after = StudyDesk(tmp_path / "state", lambda: store, lambda: 1.8e9)
    after.recover()
    [rec] = type1_records(store)
    assert rec.status == "aborted" and rec.releases == tuple(kept) and "interrupted" in str(rec.error)
    assert not d.file.path.exists() and after.progress() is None
    # a daemon that stops stores its running study itself
    assert start(after, r)[0] == "done" and after.file.path.exists()
    after.interrupt("the daemon stopped")
    assert type1_records(store)[0].error == "interrupted: the daemon stopped" and not after.file.path.exists()
