"""Precision as a figure of merit: the spread of ω_n between releases of one object, moi against a plain fit.

Honesty (releases agree within the u moi states) is not enough: the spread
between releases of one object must be no wider than that of the plainest fit
that would do, a damped sinusoid y = c + e^(−σt)·(A·cos ω_d t + B·sin ω_d t)
fitted to the whole record (ω_n = √(ω_d² + σ²)). For every set in data/,
each release is identified by moi alone (``moi identify FILE``: what a
one-release recipe and a file given to the command line get), by moi
jointly (the releases together, as ``moi identify A B C`` does, which weighs
the laws a release adds across its sisters), by ``moi --no-discover`` (each
release alone, the declared model only) and by that damped sinusoid; per
object the table gives the spread (max − min)/mean of ω_n and the worst
pairwise |Δω_n|/√(u_i² + u_j²) (for the damped sinusoid its fit σ under
white noise, which is what such a fit would state). Beside moi's one-release
ω_n, the frequency at the record's own swing that the same identification
counts (2π over the fitted swing's mean period): where a release keeps a
restoring law and its sisters do not, or the law's small-swing limit is read
far below the amplitudes the record holds, the headline ω_n scatters between
releases while this one does not; the detail names the model each release's
ω_n came from.

Coverage of one release: the share of the pairs of releases of one object,
each identified alone (its u with the scatter between releases it counts: the
documented default, the rig files here keeping no calibration figure), whose
difference lies within 2 combined u
(|Δω_n| ≤ 2·√(u_i² + u_j²)): what a user who measures a part once and then
again sees. Besides data/, the phone-gyro recording of a racquet hung as a
physical pendulum (../shared/real/userdata/phyphox_racquet_x_14-02-08, as
phyphox exported it), cut at its authors' own windows (meta/segments.csv; of
two windows that overlap, the first), when that folder is there.

    .venv/bin/python bench/bench_precision.py            # every set (several minutes)
    .venv/bin/python bench/bench_precision.py bicycle    # the sets whose name holds "bicycle"
"""

from __future__ import annotations

import csv
import itertools
import math
import statistics
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # the plain fit is the tests' reference

from measurement.errors import MeasurementError  # noqa: E402
from measurement.identification import Options, identify  # noqa: E402
from measurement.joint import identify_releases  # noqa: E402
from measurement.rig import Rig  # noqa: E402
from measurement.trace import Trace  # noqa: E402
from service.sources.dispatch import load_source  # noqa: E402
from service.sources.files import read_rig  # noqa: E402
from tests.measurement.reference import damped_sinusoid as plain_fit  # noqa: E402


def _bicycle(part: str, n: int, rate: bool) -> list[tuple[str, str]]:
    suffix = "_rate" if rate else ""
    return [(f"data/bicycle_{part}_first_{i}{suffix}.csv", f"data/bicycle_{part}_first_{i}_rig.toml") for i in range(1, n + 1)]


#: (object, [(trace, rig)] of its releases)
SETS: list[tuple[str, list[tuple[str, str]]]] = [
    ("cart pendulum, encoder", [(f"data/cart_pendulum_{a}deg.csv", "examples/cart_pendulum.toml") for a in (20, 40, 80, 180)]),
    ("bifilar suspension, IMU", [(f"data/bifilar_yaw_{a}deg.csv", "examples/bifilar_yaw.toml") for a in (65, 86)]),
    ("wood pendulum, as tracked", [(f"data/wood_pendulum_{a}deg.csv", "examples/wood_pendulum.toml") for a in (60, 120)]),
    ("wood pendulum, view measured", [(f"data/wood_markers_{a}deg.csv", "examples/wood_pendulum.toml") for a in (60, 120)]),
    ("bicycle rod, torsion, angle", _bicycle("rod_torsional", 5, False)),
    ("bicycle rod, torsion, rate", _bicycle("rod_torsional", 5, True)),
    ("front wheel, torsion, angle", _bicycle("fwheel_torsional", 3, False)),
    ("front wheel, torsion, rate", _bicycle("fwheel_torsional", 3, True)),
    ("front wheel, compound, angle", _bicycle("fwheel_compound", 3, False)),
    ("front wheel, compound, rate", _bicycle("fwheel_compound", 3, True)),
]

#: a phone's gyro (phyphox's CSV export) on a racquet hung by its butt: the authors' masses and pivot distance
RACQUET = ROOT.parent / "shared" / "real" / "userdata" / "phyphox_racquet_x_14-02-08"
RACQUET_RIG = Rig(kind="compound", mass=0.285 + 0.17228, com_distance=0.413, g=9.81, declared=("viscous",))


def racquet_windows() -> list[tuple[float, float]]:
    """The authors' windows (s of the recording's clock), the later of two that overlap left out."""
    with open(RACQUET / "meta" / "segments.csv", encoding="utf-8") as fh:
        rows = [(float(r["start"]), float(r["end"])) for r in csv.DictReader(fh, skipinitialspace=True)]
    kept: list[tuple[float, float]] = []
    for a, b in sorted(rows):
        if not kept or a >= kept[-1][1]:
            kept.append((a, b))
    return kept


if RACQUET.is_dir():
    SETS.append(("racquet, phone gyro (phyphox)", [(f"racquet:{a}:{b}", "racquet") for a, b in racquet_windows()]))


def load_trace(ref: str) -> Trace:
    """A release: a file in the repo, or ``racquet:START:END``, the racquet's gyro x rate cut to that window."""
    if not ref.startswith("racquet:"):
        return load_source(ROOT / ref)
    _, a, b = ref.split(":")
    with open(RACQUET / "Raw Data.csv", encoding="utf-8") as fh:
        rows = np.array([[float(r[0]), float(r[1])] for r in list(csv.reader(fh))[1:]])
    cut = rows[(rows[:, 0] >= float(a)) & (rows[:, 0] <= float(b))]
    return Trace(cut[:, 0] - cut[0, 0], cut[:, 1], source=f"racquet {a}–{b} s", quantity="rate")


def load_rig(ref: str) -> Rig:
    return RACQUET_RIG if ref == "racquet" else read_rig(ROOT / ref)


METHODS = ("damped sinusoid", "moi --no-discover", "moi, one release", "moi, at its swing", "moi, joint")


@dataclass(frozen=True)
class Estimate:
    omega_n: float  # rad/s
    u: float        # rad/s: the u the method states
    note: str = ""  # effects added, or why there is no estimate


def damped_sinusoid(t: np.ndarray, y: np.ndarray) -> Estimate:
    """ω_n of y = c + e^(−σt)(A cos ω_d t + B sin ω_d t) fitted to every sample (tests/measurement/reference.py)."""
    wn, s = plain_fit(t, y)
    return Estimate(wn, s) if math.isfinite(wn) else Estimate(wn, s, "no swing")


def _failed(exc: Exception) -> Estimate:
    # e.g. a sensor this version cannot read: the message without the file's path
    return Estimate(float("nan"), float("nan"), f"error: {str(exc).split(': ', 1)[-1][:50]}")


def moi_alone(trace_file: str, rig_file: str, discover: bool = True) -> tuple[Estimate, Estimate]:
    """``moi identify FILE`` (``--no-discover`` without ``discover``): (ω_n, the frequency at the record's swing).

    The latter is 2π over the fitted swing's period counted between its zero crossings (``Periods.counted``),
    with ω_n's relative u: what a stopwatch on the same record reads, whatever law the headline took ω_n from.
    """
    try:
        res = identify(load_trace(trace_file), load_rig(rig_file), Options(discover=discover))
    except MeasurementError as exc:
        return _failed(exc), _failed(exc)
    u = res.omega_n_u or res.omega_n_std
    repro = res.reproducibility
    if repro is not None and repro.counted and repro.relative is not None:
        # one release's u counts the scatter between releases its record cannot see (the documented default here)
        u = math.hypot(u, repro.relative * res.omega_n)
    note = f"{', '.join(res.added_effects) or '-'} [ω_n from {res.omega_n_from}]"
    head = Estimate(res.omega_n, u, note)
    counted = res.periods.counted if res.periods is not None else None
    if counted is None:
        return head, Estimate(float("nan"), float("nan"), "fewer than three swings")
    at = 2 * math.pi / counted
    return head, Estimate(at, u * at / res.omega_n, note)


def moi_together(releases: list[tuple[str, str]]) -> tuple[list[Estimate], str]:
    """``moi identify A B C``: each release's own ω_n ± u, and the set's flags."""
    try:
        j = identify_releases([load_trace(f) for f, _ in releases], load_rig(releases[0][1]))
    except MeasurementError as exc:
        return [_failed(exc)] * len(releases), ""
    return [Estimate(r.omega_n, r.omega_n_u or r.omega_n_std, ", ".join(r.added_effects) or "-") for r in j.releases], \
        ", ".join(j.flags)


def spread(estimates: list[Estimate]) -> tuple[float, float]:
    """(max − min)/mean of ω_n (%), and the worst pairwise |Δω_n|/√(u_i² + u_j²)."""
    w = [e.omega_n for e in estimates]
    if not all(math.isfinite(x) for x in w):
        return float("nan"), float("nan")
    z = max((abs(a.omega_n - b.omega_n) / math.hypot(a.u, b.u) for a, b in itertools.combinations(estimates, 2)),
            default=float("nan"))
    return 100 * (max(w) - min(w)) / statistics.fmean(w), z


def measure(sets: list[tuple[str, list[tuple[str, str]]]]) -> list[tuple[str, dict[str, list[Estimate]], str]]:
    out = []
    for name, releases in sets:
        per: dict[str, list[Estimate]] = {m: [] for m in METHODS}
        for trace_file, rig_file in releases:
            trace = load_trace(trace_file)
            per["damped sinusoid"].append(damped_sinusoid(trace.t, trace.angle))
            per["moi --no-discover"].append(moi_alone(trace_file, rig_file, discover=False)[0])
            head, at = moi_alone(trace_file, rig_file)
            per["moi, one release"].append(head)
            per["moi, at its swing"].append(at)
        per["moi, joint"], flags = moi_together(releases)
        out.append((name, per, flags))
    return out


def table(rows: list[tuple[str, dict[str, list[Estimate]], str]]) -> str:
    head = ("| object (releases) | " + " | ".join(f"{m}: spread, worst z" for m in METHODS)
            + " | moi / sinusoid (one release / at its swing / joint) | moi's added effects (joint); the set's flags |")
    lines = [head, "|" + "---|" * (len(METHODS) + 3)]
    ratios: dict[str, list[float]] = {m: [] for m in METHODS}
    for name, per, flags in rows:
        cells = []
        for m in METHODS:
            s, z = spread(per[m])
            ratios[m].append(s)
            cells.append("–" if not math.isfinite(s) else f"{s:.3f} %, {z:.2f}")
        s_sin = spread(per["damped sinusoid"])[0]
        ratio = " / ".join(f"{s / s_sin:.2f}" if math.isfinite(s) and s_sin > 0 else "–"
                           for s in (spread(per[m])[0] for m in ("moi, one release", "moi, at its swing", "moi, joint")))
        notes = "; ".join(e.note for e in per["moi, joint"]) + (f"; **{flags}**" if flags else "")
        lines.append(f"| {name} ({len(per['moi, joint'])}) | " + " | ".join(cells) + f" | {ratio} | {notes} |")
    med = []
    for m in METHODS:
        finite = [s for s in ratios[m] if math.isfinite(s)]
        med.append(f"{statistics.median(finite):.3f} % ({len(finite)} objects)" if finite else "–")
    lines.append("| median spread | " + " | ".join(med) + " | | |")
    return "\n".join(lines)


def coverage(rows: list[tuple[str, dict[str, list[Estimate]], str]], method: str) -> tuple[int, int, float]:
    """(pairs of releases of one object within 2 combined u, pairs, the worst |Δω_n|/√(u_i² + u_j²))."""
    within = total = 0
    worst = 0.0
    for _, per, _ in rows:
        for a, b in itertools.combinations(per[method], 2):
            z = abs(a.omega_n - b.omega_n) / math.hypot(a.u, b.u)
            if not math.isfinite(z):
                continue
            total += 1
            within += z <= 2.0
            worst = max(worst, z)
    return within, total, worst


def coverage_lines(rows: list[tuple[str, dict[str, list[Estimate]], str]]) -> str:
    lines = ["coverage: pairs of releases of one object within 2 combined u (|Δω_n| ≤ 2·√(u_i² + u_j²))"]
    for m in METHODS:
        within, total, worst = coverage(rows, m)
        share = f"{100 * within / total:.0f} %" if total else "–"
        lines.append(f"  {m:<20} {within}/{total} = {share}; worst pair {worst:.2f} combined u")
    return "\n".join(lines)


def detail(rows: list[tuple[str, dict[str, list[Estimate]], str]]) -> str:
    lines = []
    for name, per, _ in rows:
        lines.append(f"{name}")
        for i in range(len(per["moi, joint"])):
            cells = "  ".join(f"{per[m][i].omega_n:9.5f} ± {per[m][i].u:<8.2g}" for m in METHODS)
            lines.append(f"  release {i + 1}: {cells}  {per['moi, one release'][i].note} / {per['moi, joint'][i].note}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> None:
    argv = sys.argv[1:] if argv is None else argv
    sets = [s for s in SETS if not argv or any(a in s[0] for a in argv)]
    t0 = time.perf_counter()
    rows = measure(sets)
    print("spread of ω_n between releases of one object, (max − min)/mean, and the worst pairwise |Δω_n|/u;")
    print(f"per release ω_n ± u [rad/s]: {', '.join(METHODS)} ({time.perf_counter() - t0:.0f} s)")
    print(detail(rows))
    print()
    print(table(rows))
    print()
    print(coverage_lines(rows))


if __name__ == "__main__":
    main()
