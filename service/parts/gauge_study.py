"""A guided Type 1 gauge study: one reference part measured n times on the appliance, then Cg, Cgk, the bias and
its t-test computed (``measurement.gauge.type1_study``: the statistics and their sources).

The quality engineer starts a study for the active recipe's reference part (the check standard, or any part of
known value x_ref) with the characteristic's tolerance T and the count n (at least ``TYPE1_MIN``,
``TYPE1_RECOMMENDED`` by default), through the command ``type1`` (``service.core.vocabulary``; the web page's
door). A start is refused with the reason when the study cannot be run: no tolerance or reference value, n too
small, no recipe or a tensor recipe active, the rig's calibration due, a tensor set, another study or a
measurement running. While it runs, each stored release of its recipe counts for it (not for a part: the
reference's releases stay out of the recipe's parts and its SPC, and a check standard's are not compared with its
certificate); the progress says k of n. The engineer may
abort it (its releases stay in the store); another recipe selected aborts it too. Once n releases are counted
the figures are computed and the study is stored (``Store.record_gauge_study``) with the links to its releases;
a study that ended otherwise is stored as aborted or failed, with why.

Everything here is in SI (kg·m²); the pages convert to the recipe's display unit.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import uuid as uuidlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping

from measurement.errors import InvalidInput
from measurement.gauge import TYPE1_MIN, TYPE1_RECOMMENDED, Type1Study, type1_study
from measurement.result import IdentificationResult
from service.errors import ServiceError
from service.parts.recipes import Recipe
from service.parts.running_record import RunningRecord

log = logging.getLogger("moi.gauge")

#: the kind of a stored gauge study (``Store.gauge_studies``)
TYPE1 = "type1"
#: what the command's ``action`` may be
ACTIONS = ("start", "abort")
RUNNING, COMPLETE, ABORTED, FAILED = "running", "complete", "aborted", "failed"

#: the file in the state directory that holds the running study's record, so that a study cut short by a kill is
#: stored as aborted at the next start
OPEN_STUDY_FILE = "type1-study-open.json"

#: (status "done" or "refused", the refusal's reason in ``service.publish.replies.REASONS``, its detail)
StudyReply = tuple[str, str | None, str]


def status_words(status: str, error: str | None) -> str:
    """A study's end in words, its cause once: "aborted by op on the web page", "failed: no scatter …"."""
    if not error:
        return status
    return error if error.startswith(status) else f"{status}: {error}"


class StudyError(ServiceError, InvalidInput):
    """A study that cannot start, or an action that does not apply to it (says why)."""


@dataclass(frozen=True)
class Type1Plan:
    """What the engineer asked for: x_ref and T in kg·m², the count n."""

    reference: float
    tolerance: float
    count: int = TYPE1_RECOMMENDED

    @classmethod
    def of(cls, data: Mapping[str, Any]) -> Type1Plan:
        """The plan of a start command's data (``reference``, ``tolerance`` in kg·m², ``count``); StudyError
        saying what is missing or wrong."""
        def number(key: str, what: str) -> float:
            v = data.get(key)
            if v is None or v == "":
                raise StudyError(f"no {what}: a Type 1 study needs it")
            try:
                x = float(v)
            except (TypeError, ValueError):
                raise StudyError(f"the {what} must be a number, got {str(v)[:40]!r}") from None
            if not math.isfinite(x):
                raise StudyError(f"the {what} must be a finite number, got {str(v)[:40]!r}")
            return x

        reference = number("reference", "reference value x_ref")
        tolerance = number("tolerance", "tolerance T (USL − LSL)")
        if tolerance <= 0:
            raise StudyError(f"no tolerance: T must be above zero, got {tolerance:g} kg·m²")
        raw = data.get("count", TYPE1_RECOMMENDED)
        try:
            count = int(str(raw).strip())
        except ValueError:
            raise StudyError(f"the count n must be a whole number, got {str(raw)[:40]!r}") from None
        if count < TYPE1_MIN:
            raise StudyError(f"n = {count} is too few: a Type 1 study needs at least {TYPE1_MIN} measurements "
                             f"({TYPE1_RECOMMENDED} recommended)")
        return cls(reference, tolerance, count)


@dataclass(frozen=True)
class Type1Record:
    """A Type 1 study as stored: what was asked, the releases that counted (their measurement UUIDs and values,
    kg·m², in order), the figures once complete (``study``), why it ended otherwise (``error``); the recipe's
    display unit and decimals when it started (None: the set-up's)."""

    uuid: str
    status: str
    recipe: str
    recipe_version: str
    part_id: str | None
    quantity: str
    plan: Type1Plan
    releases: tuple[str, ...]
    values: tuple[float, ...]
    study: Type1Study | None
    error: str | None
    started_by: str
    unit: str | None = None
    decimals: int | None = None
    started_at: float | None = None
    finished_at: float | None = None

    def to_dict(self) -> dict[str, Any]:
        return {"kind": TYPE1, "uuid": self.uuid, "status": self.status, "recipe": self.recipe,
                "recipe_version": self.recipe_version, "part_id": self.part_id, "quantity": self.quantity,
                "reference": self.plan.reference, "tolerance": self.plan.tolerance, "count": self.plan.count,
                "releases": list(self.releases), "values": list(self.values),
                "study": self.study.to_dict() if self.study is not None else None, "error": self.error,
                "started_by": self.started_by, "unit": self.unit, "decimals": self.decimals,
                "started_at": self.started_at, "finished_at": self.finished_at}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Type1Record:
        study = d.get("study")
        return cls(str(d["uuid"]), str(d["status"]), str(d["recipe"]), str(d.get("recipe_version") or ""),
                   d.get("part_id"), str(d.get("quantity") or "J"),
                   Type1Plan(float(d["reference"]), float(d["tolerance"]), int(d["count"])),
                   tuple(str(u) for u in d.get("releases") or ()), tuple(float(v) for v in d.get("values") or ()),
                   Type1Study.from_dict(study) if study else None, d.get("error"), str(d.get("started_by") or ""),
                   d.get("unit"), d.get("decimals"), d.get("started_at"), d.get("finished_at"))


class Type1Run:
    """One running Type 1 study (main loop thread only)."""

    def __init__(self, recipe: Recipe, plan: Type1Plan, part_id: str | None, started_by: str,
                 started_at: float | None = None) -> None:
        if recipe.spec is None:
            raise StudyError(f"recipe {recipe.name!r} is a tensor recipe: a Type 1 study needs a recipe that "
                             "measures one quantity")
        self.recipe, self.plan, self.part_id, self.started_by = recipe, plan, part_id, started_by
        self.quantity = recipe.spec.quantity
        self.uuid = str(uuidlib.uuid4())
        self.started_at = started_at
        self.values: list[float] = []
        self.measurements: list[str] = []
        self.status = RUNNING
        self.study: Type1Study | None = None
        self.error: str | None = None

    @property
    def done(self) -> bool:
        return self.status != RUNNING

    def progress(self) -> dict[str, Any]:
        """What every page shows: k of n, the status, the instruction."""
        return {"uuid": self.uuid, "recipe": self.recipe.name, "part_id": self.part_id, "status": self.status,
                "done": len(self.values), "count": self.plan.count, "error": self.error,
                "instruction": self.instruction()}

    def instruction(self) -> str:
        if self.status == COMPLETE:
            return f"Type 1 study of {self.recipe.name}: complete ({self.plan.count} measurements)"
        if self.done:
            return f"Type 1 study of {self.recipe.name}: " + status_words(self.status, self.error)
        return (f"measure the reference part{' ' + self.part_id if self.part_id else ''}: measurement "
                f"{len(self.values) + 1} of {self.plan.count} (mount and release it the same way each time)")

    def release(self, result: IdentificationResult, measurement_id: str) -> bool:
        """Count one stored release (True), or not: it has no value of the recipe's quantity (False)."""
        if self.done:
            raise StudyError(f"the study is {self.status}; start a new one")
        value = getattr(result, self.quantity, None)
        if value is None or not math.isfinite(value):
            log.warning("Type 1 study %s: release %s has no %s; not counted", self.uuid, measurement_id, self.quantity)
            return False
        self.values.append(float(value))
        self.measurements.append(measurement_id)
        if len(self.values) >= self.plan.count:
            self._finish()
        return True

    def forget_last(self) -> None:
        """Undo the last counted release (its measurement could not be stored)."""
        if self.values:
            self.values.pop()
            self.measurements.pop()
            self.status, self.study, self.error = RUNNING, None, None

    def abort(self, why: str) -> None:
        if self.done:
            raise StudyError(f"the study is {self.status}: nothing to abort")
        self.status, self.error = ABORTED, why
        log.warning("Type 1 study %s aborted (%s); its %d release(s) stay in the store", self.uuid, why,
                    len(self.values))

    def _finish(self) -> None:
        try:
            self.study = type1_study(self.values, self.plan.reference, self.plan.tolerance)
            self.status = COMPLETE
        except InvalidInput as exc:  # no scatter at all: the resolution is too coarse for the study
            self.status, self.error = FAILED, str(exc)

    def record(self, finished_at: float | None = None) -> Type1Record:
        r = self.recipe
        return Type1Record(self.uuid, self.status, r.name, r.version, self.part_id, self.quantity, self.plan,
                           tuple(self.measurements), tuple(self.values), self.study, self.error, self.started_by,
                           r.display_unit, r.display_decimals, self.started_at, finished_at)


def running_file(state_dir: str | Path) -> RunningRecord:
    """The running study's record in ``state_dir`` (``OPEN_STUDY_FILE``)."""
    return RunningRecord(Path(state_dir) / OPEN_STUDY_FILE, "Type 1 study")


def running_study(state_dir: str | Path) -> Type1Record | None:
    """The study running now as its file keeps it (None: none runs, or its file cannot be read)."""
    kept = running_file(state_dir).read()
    try:
        return Type1Record.from_dict(kept) if kept is not None else None
    except (ValueError, KeyError, TypeError):
        return None


class StudyDesk:
    """The daemon's Type 1 study (main loop thread). state_dir: where the running study's record is kept
    (``OPEN_STUDY_FILE``); store(): the result store (None before start and after stop); wall_clock: Unix time, s."""

    def __init__(self, state_dir: str | Path, store: Callable[[], Any], wall_clock: Callable[[], float]) -> None:
        self.file = running_file(state_dir)
        self._store, self._now = store, wall_clock
        self.current: Type1Run | None = None  # running, or just finished (shown until the next one starts)

    def act(self, data: Mapping[str, Any], source: str, *, recipe: Recipe | None, part_id: str | None,
            busy: bool, other: str | None, block: str | None, who: str | None = None) -> StudyReply:
        """The command's ``action`` (start | abort) from ``source``. busy: a measurement runs; other: what else
        runs that a study may not overlap (a tensor set), or None; block: why the calibration refuses Measure; who:
        ``source`` in words (an abort's cause says it)."""
        action = str(data.get("action") or "")
        if action == "abort":
            return self.abort(f"aborted by {who or source}")
        if action != "start":
            return "refused", "malformed", f"unknown study action {action[:20]!r}; expected one of {', '.join(ACTIONS)}"
        running = self.current
        if running is not None and not running.done:
            return ("refused", "busy", f"a Type 1 study of {running.recipe.name} runs "
                    f"({len(running.values)} of {running.plan.count}): abort it first")
        if busy:
            return "refused", "busy", "a measurement runs: start the study when it is IDLE"
        if other is not None:
            return "refused", "busy", other
        if block is not None:
            return "refused", "calibration_due", block
        if recipe is None:
            return "refused", "malformed", "no recipe is active: select the reference part's recipe first"
        try:
            s = Type1Run(recipe, Type1Plan.of(data), part_id, source, self._now())
        except StudyError as exc:
            return "refused", "malformed", str(exc)
        self.current = s
        self._keep(s)
        log.info("Type 1 study %s started by %s (%s, part %s, x_ref %.9g kg·m², T %.9g kg·m², n %d)", s.uuid,
                 source, recipe.name, part_id or "-", s.plan.reference, s.plan.tolerance, s.plan.count)
        return "done", None, ""

    def abort(self, why: str) -> StudyReply:
        s = self.current
        if s is None or s.done:
            return "refused", "nothing_to_abort", "no Type 1 study runs"
        s.abort(why)
        self.finish(s)
        return "done", None, ""

    def of(self, recipe: Recipe | None) -> Type1Run | None:
        """The running study a release of ``recipe`` counts for (None: none runs, or it is another recipe's)."""
        s = self.current
        return s if s is not None and not s.done and recipe is not None and s.recipe is recipe else None

    def released(self, s: Type1Run) -> None:
        """A release of ``s`` is stored: the study stored once it is done."""
        log.info("Type 1 study %s: %s", s.uuid, s.instruction())
        if s.done:
            self.finish(s)
        else:
            self._keep(s)

    def selected(self, recipe: Recipe | None) -> None:
        """Another recipe selected: a running study of another recipe is aborted (its releases stay stored)."""
        s = self.current
        if s is not None and not s.done and recipe is not s.recipe:
            self.abort(f"another recipe ({recipe.name if recipe is not None else 'none'}) was selected")

    def interrupt(self, why: str) -> None:
        """The daemon stops: a running study is stored as aborted."""
        s = self.current
        if s is not None and not s.done and self._store() is not None:
            self.abort(f"interrupted: {why}")

    def finish(self, s: Type1Run) -> None:
        store = self._store()
        if store is None:
            return
        finished = self._now()
        try:
            store.record_gauge_study(s.record(finished).to_dict(), started_at=s.started_at, finished_at=finished)
        except ServiceError:
            log.exception("could not store the Type 1 study %s", s.uuid)
            return
        self.file.drop()
        if s.study is not None:
            log.info("Type 1 study %s complete: Cg %.3g, Cgk %.3g, bias %.3g kg·m² (p = %.3g)", s.uuid, s.study.cg,
                     s.study.cgk, s.study.bias.bias, s.study.bias.p)

    def progress(self) -> dict[str, Any] | None:
        return self.current.progress() if self.current is not None else None

    def _keep(self, s: Type1Run) -> None:
        """The running study's record in its file (a kill leaves it for ``recover``)."""
        self.file.keep(s.record().to_dict())

    def recover(self) -> None:
        """The study a kill cut short (its file is left): stored as aborted, with why; its releases stay stored."""
        store = self._store()
        kept = self.file.left() if store is not None else None
        if kept is None:
            return
        try:
            left = Type1Record.from_dict(kept)
        except (ValueError, KeyError, TypeError) as exc:
            self.file.damaged(exc)
            return
        why = (f"interrupted: the daemon was stopped during the study without storing it; its {len(left.values)} "
               "release(s) stay stored")
        record = dataclasses.replace(left, status=ABORTED, error=why, finished_at=self._now())
        try:
            store.record_gauge_study(record.to_dict(), started_at=left.started_at, finished_at=record.finished_at)
        except ServiceError:
            log.exception("could not store the interrupted Type 1 study %s", left.uuid)
            return
        self.file.drop()
        log.warning("Type 1 study %s (%s) was %s", left.uuid, left.recipe, why)


def type1_records(store: Any, recipe: str | None = None, status: str | None = None,
                  limit: int | None = 20) -> list[Type1Record]:
    """The stored Type 1 studies, newest first (of ``recipe``, with ``status``, when given)."""
    if store is None:
        return []
    return [Type1Record.from_dict(d) for d in store.gauge_studies(TYPE1, recipe=recipe, status=status, limit=limit)]


def latest_type1(store: Any, recipe: str | None) -> Type1Study | None:
    """The figures of the last completed Type 1 study of ``recipe`` (None: none, or no recipe), e.g. for SPC's
    capability that names the gauge's own figures (``measurement.gauge.capability_warnings``)."""
    if not recipe:
        return None
    found = type1_records(store, recipe, COMPLETE, 1)
    return found[0].study if found else None


@dataclass(frozen=True)
class StudyRelease:
    """A release a Type 1 study counted: the study (its uuid, ``None`` while it runs), and its place k of n."""

    study: str | None
    recipe: str
    index: int
    count: int

    @property
    def words(self) -> str:
        return f"Type 1 study, {self.index} of {self.count}"

    @property
    def link(self) -> str:
        return f"/type1/{self.study}" if self.study else "/type1"


def study_releases(store: Any, state_dir: str | Path | None = None, limit: int = 50) -> dict[str, StudyRelease]:
    """measurement uuid → the Type 1 study that counted it, of the latest ``limit`` stored studies and the one
    running (its file in ``state_dir``): what a page says of a release that is no part's."""
    found: dict[str, StudyRelease] = {}
    records = type1_records(store, limit=limit)
    # none running (or its file unreadable): its releases are said once it is stored
    running = running_study(state_dir) if state_dir is not None else None
    if running is not None:
        records.append(dataclasses.replace(running, uuid=""))
    for rec in records:
        for i, u in enumerate(rec.releases):
            found.setdefault(u, StudyRelease(rec.uuid or None, rec.recipe, i + 1, rec.plan.count))
    return found
