"""A rig's reproducibility between releases, from the repeat releases its store keeps.

The groups are the releases of one object: a check standard's measurements (by its name; their J, carried to
ω's scale as J^(−1/2), since J = C/ω²) and the releases of one part (by its part id, else by the part
measurement's uuid; their ω_n). They are pooled by ``measurement.reproducibility.pooled`` (ISO 5725-2): the
pooled relative within-group standard deviation of ω_n and its degrees of freedom. Only what was measured
since the rig's calibration counts: a new calibration is a new rig.

The appliance's own identifications read it through ``RigHistory``: the store is read once per calibration (0.2–0.8 s
for 3000 stored releases on a loaded 2-core machine) and the figure is then kept up to date with each release
and check standard the appliance stores, not read again for every release.
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


def _add_release(groups: Groups, m: Release) -> None:
    key = m.part_id or m.part_uuid
    if m.status == "ok" and key and _positive(m.omega_n):
        groups.setdefault(("part", key), []).append(float(m.omega_n))  # type: ignore[arg-type]


def _add_check(groups: Groups, c: Mapping[str, Any]) -> None:
    if _positive(c.get("value")):
        groups.setdefault(("check", str(c.get("name") or "check")), []).append(float(c["value"]) ** -0.5)


def repeat_groups(releases: Iterable[Release], checks: Iterable[Mapping[str, Any]]) -> list[list[float]]:
    """ω_n (or a check's J^(−1/2), on ω's scale) of each object's repeat releases, one list per object."""
    return list(_groups(releases, checks).values())


def _groups(releases: Iterable[Release], checks: Iterable[Mapping[str, Any]]) -> Groups:
    groups: Groups = {}
    for m in releases:
        _add_release(groups, m)
    for c in checks:
        _add_check(groups, c)
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

    Read from the store once per calibration (``calibrated_since``), then kept with what the appliance stores
    (``stored``, ``checked``): a release's identification does not read the store again.
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
                    log.warning("the rig's history of repeat releases not read (%s): its default is stated", exc)
                    return None
            return pooled(self._groups.values())

    def stored(self, m: Release) -> None:
        """A release the appliance stored (``Store.record``'s row) joins the history read."""
        with self._lock:
            if self._groups is not None:
                _add_release(self._groups, m)

    def checked(self, record: Mapping[str, Any]) -> None:
        """A check standard's comparison the appliance stored joins the history read."""
        with self._lock:
            if self._groups is not None:
                _add_check(self._groups, record)
