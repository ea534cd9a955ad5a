"""A rig's reproducibility between releases, from the repeat releases its store keeps.

The groups are the releases of one object: a check standard's measurements (by its name; their J, carried to
ω's scale as J^(−1/2), since J = C/ω²) and the releases of one part (by its part id, else by the part
measurement's uuid; their ω_n). They are pooled by ``measurement.reproducibility.pooled`` (ISO 5725-2): the
pooled relative within-group standard deviation of ω_n and its degrees of freedom. Only what was measured
since the rig's calibration counts: a new calibration is a new rig.
"""

from __future__ import annotations

import math
from typing import Any, Iterable, Mapping, Protocol, Sequence

from measurement.reproducibility import Reproducibility, pooled


class Release(Protocol):
    """What is read of a stored release (``service.persistence.store.StoredMeasurement``)."""

    status: str
    omega_n: float | None
    part_id: str | None
    part_uuid: str | None


class Releases(Protocol):
    """What is read of the result store (``service.persistence.store.Store``)."""

    def list(self, limit: int | None = ..., *, since: float | None = ..., status: str | None = ...) -> Any: ...

    def check_standards(self, limit: int | None = ...) -> Sequence[Mapping[str, Any]]: ...


#: the newest releases read (a page's worth of work, however long the store has grown)
READ_LIMIT = 5000


def _positive(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v > 0


def repeat_groups(releases: Iterable[Release], checks: Iterable[Mapping[str, Any]]) -> list[list[float]]:
    """ω_n (or a check's J^(−1/2), on ω's scale) of each object's repeat releases, one list per object."""
    groups: dict[tuple[str, str], list[float]] = {}
    for m in releases:
        key = m.part_id or m.part_uuid
        if m.status == "ok" and key and _positive(m.omega_n):
            groups.setdefault(("part", key), []).append(float(m.omega_n))  # type: ignore[arg-type]
    for c in checks:
        if _positive(c.get("value")):
            groups.setdefault(("check", str(c.get("name") or "check")), []).append(float(c["value"]) ** -0.5)
    return list(groups.values())


def rig_reproducibility(store: Releases, since: float | None = None) -> Reproducibility:
    """The store's repeat releases since ``since`` (s, epoch; None: all) pooled (``Reproducibility``)."""
    releases = store.list(limit=READ_LIMIT, since=since, status="ok")
    checks = [c for c in store.check_standards(limit=READ_LIMIT) if since is None or c["finished_at"] >= since]
    return pooled(repeat_groups(releases, checks))
