"""A rig's reproducibility between releases, from the repeat releases its store keeps.

The groups are the releases of one object: a check standard's measurements (by its name: the ω_n of the releases
of each of its parts the appliance measured; a comparison stored without its releases, by ``moi check-standard``,
its J carried to ω's scale as J^(−1/2), since J = C/ω², in a group of its own) and the releases of one part (by its
part id, else by the part measurement's uuid; their ω_n; not a tensor set's orientations). They are pooled by
``measurement.reproducibility.pooled`` (ISO 5725-2): the pooled relative within-group standard deviation of ω_n
and its degrees of freedom. Only what was measured since the rig's calibration counts: a new calibration is a new
rig.

The appliance's own identifications read it through ``RigHistory``: the store is read once per calibration
(0.2–0.8 s for 3000 stored releases on a loaded 2-core machine) and the figure is then kept up to date with each
release the appliance stores, not read again for every release (again after a check standard).
"""

from __future__ import annotations

import datetime as dt
import logging
import math
import threading
from typing import Any, Iterable, Mapping, Protocol, Sequence

from measurement import Rig
from measurement.reproducibility import Reproducibility, pooled
from measurement.rig import CalibrationRecord
from service.errors import StoreError

log = logging.getLogger("moi.daemon")


class Release(Protocol):
    """What is read of a stored release (``service.persistence.store.StoredMeasurement``)."""

    @property
    def uuid(self) -> str: ...

    @property
    def status(self) -> str: ...

    @property
    def omega_n(self) -> float | None: ...

    @property
    def part_id(self) -> str | None: ...

    @property
    def part_uuid(self) -> str | None: ...


class Releases(Protocol):
    """What is read of the result store (``service.persistence.store.Store``)."""

    def list(self, limit: int | None = ..., *, since: float | None = ..., status: str | None = ...) -> Any: ...

    def check_standards(self, limit: int | None = ...) -> Sequence[Mapping[str, Any]]: ...


#: the newest releases read (a page's worth of work, however long the store has grown)
READ_LIMIT = 5000


def _positive(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v > 0


Groups = dict[tuple[str, str], list[float]]


def _add_release(groups: Groups, m: Release, check: str | None = None) -> None:
    """One release's ω_n in its object's group: its check standard's (``check``: its name), else its part's. Only a
    part's release counts (its part uuid): a tensor set's six orientations under one part ID are not repeats."""
    key = m.part_id or m.part_uuid
    if m.status == "ok" and m.part_uuid and key and _positive(m.omega_n):
        groups.setdefault(("check", check) if check else ("part", key), []).append(float(m.omega_n))  # type: ignore[arg-type]


def _add_check(groups: Groups, c: Mapping[str, Any]) -> None:
    """A check standard's stored value without its releases: J^(−1/2), on ω's scale, apart from the ω_n's."""
    if _positive(c.get("value")):
        groups.setdefault(("check J", str(c.get("name") or "check")), []).append(float(c["value"]) ** -0.5)


def repeat_groups(releases: Iterable[Release], checks: Iterable[Mapping[str, Any]]) -> list[list[float]]:
    """ω_n (or a check's J^(−1/2), on ω's scale) of each object's repeat releases, one list per object."""
    return list(_groups(releases, checks).values())


def _groups(releases: Iterable[Release], checks: Iterable[Mapping[str, Any]]) -> Groups:
    # a check standard's comparison names the release that completed its part: that part's releases are the check
    # standard's (their ω_n, whatever quantity the comparison is of: J_object − the tare is not on ω's scale)
    releases = list(releases)
    by_uuid = {m.uuid: m for m in releases}
    checked: dict[str, str] = {}  # part uuid → the check standard's name
    groups: Groups = {}
    for c in checks:
        m = by_uuid.get(str(c.get("measurement")))
        if m is not None and m.part_uuid:
            checked[m.part_uuid] = str(c.get("name") or "check")
        else:
            _add_check(groups, c)
    for m in releases:
        _add_release(groups, m, checked.get(m.part_uuid or ""))
    return groups


def _read(store: Releases, since: float | None) -> Groups:
    releases = store.list(limit=READ_LIMIT, since=since, status="ok")
    checks = [c for c in store.check_standards(limit=READ_LIMIT) if since is None or c["finished_at"] >= since]
    return _groups(releases, checks)


def rig_reproducibility(store: Releases, since: float | None = None) -> Reproducibility:
    """The store's repeat releases since ``since`` (s, epoch; None: all) pooled (``Reproducibility``)."""
    return pooled(_read(store, since).values())


def calibrated_since(cal: CalibrationRecord | None) -> float | None:
    """Where a rig's history starts (s, epoch): the start (UTC) of its calibration's day; None without one."""
    return None if cal is None else dt.datetime.combine(cal.date, dt.time(), dt.UTC).timestamp()


class RigHistory:
    """The rig's repeat releases for the appliance's own identifications (any thread).

    Read from the store once per calibration (``calibrated_since``) and after a check standard (``checked``), kept
    with each release the appliance stores (``stored``) in between: a release's identification does not read the
    store again.
    """

    def __init__(self, store: Releases) -> None:
        self._store = store
        self._lock = threading.Lock()
        self._since: float | None = None
        self._groups: Groups | None = None

    def reproducibility(self, rig: Rig) -> Reproducibility | None:
        """The history of ``rig`` since its calibration, pooled; None when the store cannot be read (said)."""
        since = calibrated_since(rig.calibration)
        with self._lock:
            if self._groups is None or since != self._since:
                try:
                    self._groups, self._since = _read(self._store, since), since
                except StoreError as exc:
                    log.warning("the rig's history of repeat releases not read (%s): its calibration's figure or the default counts", exc)
                    return None
            return pooled(self._groups.values())

    def stored(self, m: Release) -> None:
        """A release the appliance stored (``Store.record``'s row) joins the history read."""
        with self._lock:
            if self._groups is not None:
                _add_release(self._groups, m)

    def checked(self) -> None:
        """The appliance stored a check standard's comparison: its part's releases, kept as a part's, are the check
        standard's; read again at the next release (a check standard is measured once a shift or a day)."""
        with self._lock:
            self._groups = None
