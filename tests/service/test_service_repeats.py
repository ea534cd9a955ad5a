"""A rig's reproducibility between releases from the repeat releases in its store (ISO 5725-2 pooling)."""

from __future__ import annotations

import math
from types import SimpleNamespace

import pytest

from service.persistence.store import Store
from service.sources.repeats import RigHistory, calibrated_since, repeat_groups, rig_reproducibility


def _release(omega_n, part_id=None, part_uuid=None, status="ok"):
    return SimpleNamespace(uuid=f"m{omega_n}-{part_id}", omega_n=omega_n, part_id=part_id, part_uuid=part_uuid,
                           status=status)


def test_releases_group_by_part_and_checks_by_name_on_the_scale_of_omega():
    releases = [_release(4.0, "A", "a1"), _release(4.004, "A", "a2"), _release(6.0, None, "u1"),
                _release(6.006, None, "u1"), _release(5.0, "B", "b1", status="failed"), _release(float("nan"), "A", "a3"),
                _release(None, "C", "c1"),
                # a tensor set's orientations under one part ID: not a part's releases, not repeats
                _release(5.0, "T"), _release(7.0, "T")]
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


class _Counted(Store):
    """The store, its reads counted."""

    reads = 0

    def list(self, *args, **kwargs):
        type(self).reads += 1
        return super().list(*args, **kwargs)


def _rig(date):
    from measurement import Rig
    from measurement.rig import CalibrationRecord

    return Rig(kind="torsion", stiffness=0.3651, calibration=None if date is None else CalibrationRecord(date=date))


def _stored(store, w, part_id=None, part_uuid=None, at=90003.0):
    return store.record(status="ok", trigger="cli", device_id="d", software_version="x", started_at=at,
                        finished_at=at + 1, result={"omega_n": w, "flags": []},
                        part={"part_id": part_id, "part_uuid": part_uuid})


def test_the_appliances_history_is_read_once_per_calibration_and_kept_with_what_it_stores(tmp_path):
    import datetime as dt

    rig = _rig(dt.date(1970, 1, 1) + dt.timedelta(days=1))
    assert calibrated_since(rig.calibration) == 86400.0 and calibrated_since(None) is None
    _Counted.reads = 0
    with _Counted(tmp_path) as store:
        history = RigHistory(store)
        for at, v in ((90000.0, 0.01250), (90001.0, 0.01252)):
            _check(store, "disc", v, at)
        first = history.reproducibility(rig)
        assert first is not None and (first.dof, first.releases) == (1.0, 2) and _Counted.reads == 1
        # two releases of one part, stored by the appliance: kept, not read again
        for w in (4.0, 4.004):
            history.stored(_stored(store, w, "A", "a"))
        kept = history.reproducibility(rig)
        assert kept is not None and _Counted.reads == 1
        read = rig_reproducibility(store, calibrated_since(rig.calibration))
        assert (kept.relative, kept.dof, kept.releases) == (pytest.approx(read.relative, rel=1e-12), 2.0, 4)
        # a check standard's comparison: read again at the next release (its part's releases are the check's)
        _check(store, "disc", 0.01248, 90010.0)
        history.checked()
        again = history.reproducibility(rig)
        assert again is not None and (again.dof, again.releases) == (3.0, 5) and _Counted.reads == 3
        # a new calibration is a new rig: read again from its day
        later = history.reproducibility(_rig(dt.date(1970, 1, 2) + dt.timedelta(days=1)))
        assert _Counted.reads == 4 and later is not None and later.relative is None


def test_a_check_standards_releases_are_pooled_by_its_name_on_their_omega_n_not_on_its_value(tmp_path):
    # the appliance's check standard (J_object: J less the tare, not on ω's scale) names the release that completed
    # its part; its parts' releases are one object's, by the check standard's name, once each
    with Store(tmp_path) as store:
        rows = [_stored(store, w, part_uuid=f"cs{i}", at=100.0 + i) for i, w in enumerate((5.40, 5.41, 5.39))]
        for i, row in enumerate(rows):
            store.record_check_standard({"name": "disc", "quantity": "J_object", "value": 0.008 + 1e-5 * i,
                                         "U": 2e-5, "reference": 0.008, "reference_U": 2e-5, "E_n": 0.1,
                                         "passed": True, "measurement": row.uuid}, finished_at=101.0 + i)
        _check(store, "disc", 0.0125, 200.0)  # `moi check-standard`: no release of its own, a group apart
        _check(store, "disc", 0.0126, 201.0)
        r = rig_reproducibility(store)
    w = [5.40, 5.41, 5.39]
    j = [0.0125**-0.5, 0.0126**-0.5]
    hand = math.sqrt((sum((x / (sum(w) / 3) - 1) ** 2 for x in w) + sum((x / (sum(j) / 2) - 1) ** 2 for x in j)) / 3)
    assert (r.groups, r.releases, r.dof) == (2, 5, 3.0)
    assert r.relative == pytest.approx(hand, rel=1e-12)
