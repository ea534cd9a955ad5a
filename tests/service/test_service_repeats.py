"""A rig's reproducibility between releases from the repeat releases in its store (ISO 5725-2 pooling)."""

from __future__ import annotations

import math
from types import SimpleNamespace

import pytest

from service.persistence.store import Store
from service.sources.repeats import repeat_groups, rig_reproducibility


def _release(omega_n, part_id=None, part_uuid=None, status="ok"):
    return SimpleNamespace(omega_n=omega_n, part_id=part_id, part_uuid=part_uuid, status=status)


def test_releases_group_by_part_and_checks_by_name_on_the_scale_of_omega():
    releases = [_release(4.0, "A"), _release(4.004, "A"), _release(6.0, None, "u1"), _release(6.006, None, "u1"),
                _release(5.0, "B", status="failed"), _release(float("nan"), "A"), _release(None, "C")]
    checks = [{"name": "disc", "value": 0.0125}, {"name": "disc", "value": 0.0126}, {"name": "bar", "value": -1.0}]
    groups = repeat_groups(releases, checks)
    assert sorted(map(len, groups)) == [2, 2, 2]
    assert [4.0, 4.004] in groups and [6.0, 6.006] in groups
    assert [0.0125**-0.5, 0.0126**-0.5] in groups


def _check(store, name, value, at):
    store.record_check_standard({"name": name, "quantity": "J_object", "value": value, "U": 2e-5,
                                 "reference": 0.0125, "reference_U": 2e-5, "E_n": 0.1, "passed": True},
                                finished_at=at)


def test_a_store_of_check_standards_pools_their_scatter_since_the_calibration(tmp_path):
    with Store(tmp_path) as store:
        _check(store, "disc", 0.0200, at=100.0)  # before the calibration: another rig
        for at, v in ((200.0, 0.01250), (201.0, 0.01252), (202.0, 0.01248)):
            _check(store, "disc", v, at)
        r = rig_reproducibility(store, since=150.0)
    # by hand: ω's scale J^(−1/2); the relative deviations of one group of three, 2 degrees of freedom
    w = [v**-0.5 for v in (0.01250, 0.01252, 0.01248)]
    m = sum(w) / 3
    hand = math.sqrt(sum((x / m - 1) ** 2 for x in w) / 2)
    assert r.relative == pytest.approx(hand, rel=1e-12)
    assert r.relative == pytest.approx(0.5 * 0.0016, rel=0.01)  # J's 0.16 % is ω's 0.08 %
    assert (r.dof, r.groups, r.releases, r.source) == (2.0, 1, 3, "history")


def test_an_empty_store_knows_no_reproducibility(tmp_path):
    with Store(tmp_path) as store:
        r = rig_reproducibility(store)
    assert r.relative is None and not r.known
