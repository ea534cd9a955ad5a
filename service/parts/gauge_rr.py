"""A recipe's Gauge R&R (AIAG "Measurement Systems Analysis", 4th edition, ANOVA method) from the store's
records: which records make the study (parts × appraisers × trials), what a balanced study still lacks, and
the figures of its complete parts (``measurement.gauge.gauge_rr``).

A record is one trial of its part (its part ID) by its appraiser: the run's operator (the web user who pressed
Measure, else the door that started it: "button", "modbus", "mqtt" …) or, to compare the appliances of a fleet,
the appliance that measured it (its device id). A trial is a completed measurement of the part (its value, as
its verdict used it), or by choice each release. INVALID results and records without a part ID count for no
part; a part measured only once (production, not a study) is left out and counted.

The ANOVA wants a balanced design: every part measured the same number of times r by every appraiser. r is the
number asked for, else the most common count. A part that lacks an appraiser's trials is listed with what it
lacks and stays out of the figures until it has them; an appraiser's trials beyond r are not used (the first r
are) and are said. Which parts and appraisers make the study is the quality engineer's choice: the page offers
it, this module only reports what the records hold.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field, replace
from typing import Any, Mapping, Sequence

from measurement.gauge import GaugeRR, GaugeStudyError, gauge_rr
from service.parts.outcome import PartOutcome

#: who the appraisers are: the run's operator, or the appliance that measured it
BY = {"operator": "operator", "device": "appliance (device id)"}
#: what one trial is: a completed measurement of the part, or each release
TRIALS = {"part": "each completed measurement of a part (its value)", "release": "each release of a part"}
#: the latest records a study reads at most (a study has tens; a date range narrows a long history)
MAX_RECORDS = 2000


@dataclass(frozen=True)
class Shortfall:
    """A part an appraiser measured ``have`` times where the study uses ``want`` trials (fewer: it lacks them;
    more: only the first ``want`` are used)."""

    part: str
    appraiser: str
    have: int
    want: int

    @property
    def words(self) -> str:
        if self.have < self.want:
            lacks = "all" if self.have == 0 else f"{self.want - self.have} of the"
            return f"{self.appraiser}: lacks {lacks} {self.want} trials"
        return f"{self.appraiser}: {self.have} trials, the first {self.want} used"


@dataclass(frozen=True)
class RecipeGrr:
    """What the records of one recipe hold for a Gauge R&R, and its figures (None: not yet; ``why`` says why).

    parts: the parts measured more than once by the study's appraisers, in the order first measured;
    appraisers: the study's (``chosen``), of ``found`` (all who measured those parts); counts[part][appraiser]:
    the trials each has; trials: r; lacking: the parts still short of trials (not in the figures); beyond: the
    trials not used; complete: the parts in the figures; single: parts measured only once (left out);
    left_out: records that count for no part (INVALID, no value, no part ID); read: records read (``truncated``:
    the latest ``MAX_RECORDS`` only); spec: the recipe as its newest record was judged with (lower, upper:
    kg·m²); first, last: the period of the records read (Unix s). Values kg·m² (``study``: SI).
    """

    recipe: str
    by: str
    trial: str
    parts: tuple[str, ...] = ()
    found: tuple[str, ...] = ()
    appraisers: tuple[str, ...] = ()
    counts: Mapping[str, Mapping[str, int]] = field(default_factory=dict)
    trials: int = 0
    lacking: tuple[Shortfall, ...] = ()
    beyond: tuple[Shortfall, ...] = ()
    complete: tuple[str, ...] = ()
    single: int = 0
    left_out: int = 0
    read: int = 0
    truncated: bool = False
    spec: Mapping[str, Any] | None = None
    first: float | None = None
    last: float | None = None
    study: GaugeRR | None = None
    why: str | None = None

    @property
    def tolerance(self) -> float | None:
        """USL − LSL of the recipe, kg·m² (None: no two-sided limits)."""
        s = self.spec or {}
        lo, hi = s.get("lower"), s.get("upper")
        return float(hi) - float(lo) if isinstance(lo, (int, float)) and isinstance(hi, (int, float)) and hi > lo \
            else None

    def lacks(self, part: str) -> tuple[Shortfall, ...]:
        """What ``part`` still lacks for a balanced study (empty: complete)."""
        return tuple(s for s in self.lacking if s.part == part)


@dataclass(frozen=True)
class _Trial:
    part: str
    appraiser: str
    value: float  # kg·m²


def _trial(m: Any, by: str, trial: str) -> _Trial | None:
    """The trial a stored measurement is (None: it counts for no part)."""
    if not m.part_id:
        return None
    if trial == "part":
        value = m.part_value if m.part_verdict != "INVALID" else None
    else:
        release = PartOutcome.from_dict(m.payload).release
        value = release.value if release is not None and release.verdict != "INVALID" else None
    if not isinstance(value, (int, float)):
        return None
    appraiser = m.operator if by == "operator" else m.device_id
    return _Trial(str(m.part_id), str(appraiser), float(value))


def _usual(counts: Sequence[int]) -> int:
    """The most common of the non-zero counts (a tie: the larger)."""
    seen = Counter(c for c in counts if c > 0)
    return max(seen, key=lambda c: (seen[c], c)) if seen else 0


def recipe_grr(store: Any, recipe: str, *, since: float | None = None, until: float | None = None,
               by: str = "operator", trial: str = "part", appraisers: Sequence[str] | None = None,
               trials: int | None = None, limit: int = MAX_RECORDS) -> RecipeGrr:
    """The Gauge R&R of ``recipe``'s records in the store finished in [since, until) (see the module docstring).

    by: "operator" or "device"; trial: "part" or "release"; appraisers: the study's (default: every one who
    measured a part more than once); trials: r (default: the most common count).
    """
    if by not in BY or trial not in TRIALS:
        raise ValueError(f"by {by!r}, trial {trial!r}: expected one of {list(BY)} and of {list(TRIALS)}")
    # a part's value is a column; a release's is in the payload, read only then
    rows = list(reversed(store.list(limit=limit, recipe=recipe, since=since, until=until, status="ok",
                                    parts_only=trial == "part", full=trial == "release")))
    newest = (rows[-1] if trial == "release" else store.get(rows[-1].uuid)) if rows else None
    head = RecipeGrr(recipe, by, trial, read=len(rows), truncated=len(rows) >= limit,
                     spec=PartOutcome.from_dict(newest.payload).recipe if newest is not None else None,
                     first=rows[0].finished_at if rows else None, last=rows[-1].finished_at if rows else None)
    made = [(m, _trial(m, by, trial)) for m in rows]
    kept = [t for _, t in made if t is not None]
    left_out = len(made) - len(kept)
    cells: dict[str, dict[str, list[float]]] = {}
    for t in kept:
        cells.setdefault(t.part, {}).setdefault(t.appraiser, []).append(t.value)
    again = [p for p, by_part in cells.items() if sum(map(len, by_part.values())) > 1]
    found = tuple(dict.fromkeys(a for p in again for a in cells[p]))
    # none of the asked-for appraisers among these (the appraisers were switched between operators and
    # appliances): all of them, as when none is asked for
    chosen = tuple(a for a in found if appraisers is not None and a in appraisers) or found
    counts = {p: {a: len(cells[p].get(a, ())) for a in chosen} for p in again}
    parts = tuple(p for p in again if sum(counts[p].values()) > 1)
    single = len(cells) - len(again)
    r = trials if trials is not None else _usual([n for p in parts for n in counts[p].values()])
    short = [Shortfall(p, a, counts[p][a], r) for p in parts for a in chosen if counts[p][a] != r]
    lacking = tuple(s for s in short if s.have < r)
    complete = tuple(p for p in parts if all(counts[p][a] >= r for a in chosen))
    got = replace(head, parts=parts, found=found, appraisers=chosen, counts={p: counts[p] for p in parts},
                  trials=r, lacking=lacking, beyond=tuple(s for s in short if s.have > r), complete=complete,
                  single=single, left_out=left_out)
    why = _not_yet(len(rows), chosen, complete, r)
    if why is not None:
        return replace(got, why=why)
    values = [[cells[p][a][:r] for a in chosen] for p in complete]
    try:
        return replace(got, study=gauge_rr(values, tolerance=got.tolerance, parts=complete, appraisers=chosen))
    except GaugeStudyError as exc:  # no scatter at all: the values say why
        return replace(got, why=str(exc))


def _not_yet(read: int, appraisers: Sequence[str], complete: Sequence[str], r: int) -> str | None:
    """Why the records make no study yet (None: they make one)."""
    if read == 0:
        return "no measurements of this recipe in the period"
    if len(appraisers) < 2:
        return (f"a Gauge R&R needs at least 2 appraisers who measured the same parts more than once; "
                f"found {len(appraisers)}" + (f" ({', '.join(appraisers)})" if appraisers else ""))
    if r < 2:
        return f"a Gauge R&R needs at least 2 trials of each part by each appraiser; the study asks for {r}"
    if len(complete) < 2:
        return (f"a Gauge R&R needs at least 2 parts measured {r} times by each of {', '.join(appraisers)}; "
                f"{len(complete)} {'is' if len(complete) == 1 else 'are'} complete")
    return None
