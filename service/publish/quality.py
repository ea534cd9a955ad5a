"""What the pages and the report say about a part: its verdict first, the value in the display unit, the
tolerance band with the guard band and the result's interval, the shift's counters, control charts as SVG.

Pure functions of stored payloads and their typed results (``service.publish.payload.stored_result``: the result's
fields; ``service.parts.outcome.PartOutcome``: the part's; the recipe stays its dict form) and numbers: the views, the report page
and the PDF share them. Every number is written with its unit; a missing value is written as "–", never as None or
nan.
"""

from __future__ import annotations

import datetime as dt
import math
import re
from typing import TYPE_CHECKING, Any, Callable, Mapping, Sequence

from measurement.units import SI, UnitError, from_si, inertia_unit
from service.parts.outcome import PartOutcome
from service.publish.budget import budget_rows

if TYPE_CHECKING:  # pragma: no cover
    from measurement.result import IdentificationResult

#: what the page says for a value it does not have
MISSING = "–"

#: verdict words (colour is never the only sign: the word is always written)
VERDICT_WORDS = {"OK": "part OK", "NOK": "part NOK (not conforming)", "INVALID": "part INVALID (measure again)"}


def _plain_g(x: float, spec: str) -> str:
    """``x`` with the significant digits of a "g" spec (".7g", "+.3g"), in fixed-point: never e-notation."""
    sign = "+" if spec.startswith("+") else ""
    digits = int(spec.strip("+").lstrip(".").rstrip("g") or 6)
    if x == 0:
        return f"{x:{sign}.0f}"
    decimals = max(0, digits - 1 - int(math.floor(math.log10(abs(x)))))
    text = f"{x:{sign}.{decimals}f}"
    # "g" drops trailing zeros; so does this, with its decimal point
    return text.rstrip("0").rstrip(".") if "." in text else text


#: a number in e-notation inside a sentence (1.2e-05, 9e+03)
_E_NUMBER = re.compile(r"(?<![\w.])([+-]?)(\d+(?:\.(\d+))?)[eE]([+-]?\d+)\b")


def plain_text(text: Any) -> str:
    """``text`` with every number in e-notation written out in fixed-point with its significant digits (the
    sentences of the identification and the verdict are made for logs; a person reads them without exponents)."""
    def fixed(m: re.Match) -> str:
        digits = len((m.group(2) or "").replace(".", "").lstrip("0")) or 1
        return m.group(1) + _plain_g(float(m.group(2) + "e" + m.group(4)), f".{digits}g")

    return _E_NUMBER.sub(fixed, str(text)) if text is not None else MISSING


#: an inertia inside a sentence of the verdict: "1.2e-05 kg·m²", or the limits "[1.1e-05, 1.3e-05] kg·m²"
_SI_INERTIA = re.compile(r"(\[)?([+-]?\d+(?:\.\d*)?(?:[eE][+-]?\d+)?)(?:, ([+-]?\d+(?:\.\d*)?(?:[eE][+-]?\d+)?)\])?"
                         r" kg·m²")


def reason(text: Any, unit: str = SI, decimals: int = 6) -> str:
    """A sentence of the verdict (written in kg·m² with as many digits as a log keeps) with every inertia in it
    in ``unit`` and ``decimals`` (the part's, as the tile above it), never fewer than two significant digits (a
    small uncertainty is not written as 0); other numbers as ``plain_text`` writes them."""
    def shown(x: str) -> str:
        return spread(float(x), unit, decimals).removesuffix(f" {unit}")

    def convert(m: re.Match) -> str:
        if m.group(1) and m.group(3):
            return f"[{shown(m.group(2))}, {shown(m.group(3))}] {unit}"
        return f"{m.group(1) or ''}{shown(m.group(2))} {unit}"

    return plain_text(_SI_INERTIA.sub(convert, str(text))) if text is not None else MISSING


def number(v: Any, spec: str | int = ".6g") -> str:
    """A number as text, never in e-notation (a "g" spec keeps its significant digits in fixed-point; an int:
    that many decimals); None, NaN, ±inf and non-numbers that are not text become "–"."""
    if v is None or isinstance(v, bool):
        return MISSING
    if isinstance(v, (int, float)):
        if not math.isfinite(v):
            return MISSING
        if isinstance(spec, int):
            return f"{v:.{max(0, spec)}f}"
        return _plain_g(float(v), spec) if spec.endswith("g") else format(v, spec)
    return str(v)


def inertia(v: Any, unit: str = SI, spec: str | int = ".7g") -> str:
    """``v`` kg·m² written in ``unit`` with the unit ("–" without a value); ``spec``: significant digits as a
    "g" spec, or an int: decimals (a recipe's, ``places``)."""
    shown = from_si(v, unit) if isinstance(v, (int, float)) and not isinstance(v, bool) else None
    return MISSING if shown is None else f"{signed(number(shown, spec))} {unit}"


def spread(v: Any, unit: str = SI, places: int = 6) -> str:
    """An uncertainty or a scatter ``v`` kg·m² in ``unit``: with the part's ``places``, never fewer than two
    significant digits (a small U is not written as 0): the one rule of the pages, the reports and the verdict's
    sentences."""
    shown = from_si(v, unit) if isinstance(v, (int, float)) and not isinstance(v, bool) else None
    if shown is None or not math.isfinite(shown):
        return MISSING
    d = places if shown == 0 else max(places, 1 - int(math.floor(math.log10(abs(shown)))))
    return f"{signed(number(shown, min(d, 12)))} {unit}"


def signed(text: str) -> str:
    """A number's text with the minus sign (U+2212) a page writes, not the ASCII hyphen."""
    return "−" + text[1:] if text.startswith("-") else text


def places(recipe: Mapping[str, Any] | None, unit: str = SI, U: float | None = None) -> int:
    """Decimals a person reads a value of ``recipe`` with in ``unit``: the recipe's ``display_decimals``, else
    those that resolve a hundredth of its tolerance; without a tolerance, those of U to two significant digits
    (else seven significant digits)."""
    r = recipe or {}
    given = r.get("display_decimals")
    if isinstance(given, int) and not isinstance(given, bool):
        return given
    f = from_si(1.0, unit) or 1.0
    step = None
    if r.get("upper") is not None and r.get("nominal") is not None:
        step = abs(float(r["upper"]) - float(r["nominal"])) * f / 100.0
    elif U is not None and math.isfinite(U) and U > 0:
        step = U * f / 10.0
    if not step:
        return 6
    return max(0, min(12, int(math.ceil(-math.log10(step) - 1e-9))))


def iso(ts: float | None) -> str:
    """Unix time (s) as ISO 8601 with its UTC offset, to the second ("–" without one): exports and APIs."""
    if ts is None or not math.isfinite(ts):
        return MISSING
    return dt.datetime.fromtimestamp(ts, dt.UTC).isoformat(timespec="seconds")


#: how a person reads a time on the pages unless [web] time_format says otherwise (local time)
TIME_FORMAT = "%Y-%m-%d %H:%M:%S"


def local_time(ts: float | None, fmt: str = TIME_FORMAT) -> str:
    """Unix time (s) as the appliance's local time in ``fmt`` (strftime), "–" without one: what a person reads."""
    if ts is None or not isinstance(ts, (int, float)) or not math.isfinite(ts):
        return MISSING
    return dt.datetime.fromtimestamp(ts).astimezone().strftime(fmt)


def judgement(view: Mapping[str, Any], unit: str = SI) -> dict[str, Any] | None:
    """Why a part has its verdict, in the recipe's decimals: nominal, limits, the deviation from the nominal in %
    and where the value lies ("below LSL", "within the limits", ...); None without limits or value."""
    r = view.get("recipe") or {}
    value, U = view.get("value"), view.get("U")
    if r.get("lower") is None or r.get("upper") is None or r.get("nominal") is None:
        return None
    n = places(r, unit, U)
    lsl, usl, nominal = float(r["lower"]), float(r["upper"]), float(r["nominal"])
    out: dict[str, Any] = {"places": n, "nominal": inertia(nominal, unit, n),
                           "limits": f"{inertia(lsl, unit, n)} … {inertia(usl, unit, n)}",
                           "tolerance": inertia(usl - nominal, unit, n), "deviation": None, "where": None}
    if not isinstance(value, (int, float)) or not math.isfinite(value):
        return out
    u = float(U) if isinstance(U, (int, float)) and math.isfinite(U) else 0.0
    if value < lsl:
        where = "below LSL"
    elif value > usl:
        where = "above USL"
    elif u and value - u < lsl:
        where = "within the limits, but U reaches below LSL"
    elif u and value + u > usl:
        where = "within the limits, but U reaches above USL"
    else:
        where = "within the limits"
    out.update(deviation=percent(100.0 * (value - nominal) / nominal), where=where)
    return out


def percent(v: float) -> str:
    """A signed deviation in % to one decimal; one that rounds to nothing is "0.0 %", never "−0.0 %" nor "+0.0 %"."""
    shown = round(v, 1)
    if shown == 0:
        return "0.0 %"
    return f"{signed(number(shown, '+.1f'))} %"


def display_unit(payload: Mapping[str, Any] | None, default: str = SI) -> str:
    """The unit a result is shown in: its recipe's, else ``default`` (the set-up's)."""
    recipe = (payload or {}).get("recipe") or {}
    try:
        return inertia_unit(recipe.get("display_unit") or default)
    except UnitError:  # a unit this version does not know (a newer recipe): SI
        return SI


def plot_labels(stored: Any, result: IdentificationResult | None, simulated: bool,
                default_unit: str = SI) -> tuple[str, str | None]:
    """(unit, title source) of a result's plot (``stored``: its stored measurement, ``result``: its typed result):
    its recipe's display unit, and "measurement #N" with the sensor that took it (the simulated rig said as such,
    whatever sensor it imitates)."""
    payload = getattr(stored, "payload", None) or {}
    unit = display_unit(payload, default_unit)
    seq = getattr(stored, "seq", None)
    acquisition = result.acquisition if result is not None else {}
    sensor = "simulated rig" if simulated else next((k for k in ("camera", "encoder") if k in acquisition),
                                                    (result.source if result is not None else None) or "sensor")
    part = payload.get("part_id")
    head = f"measurement #{seq}" if seq is not None else "measurement"
    return unit, f"{head}{f', part {part}' if part else ''}, {sensor}"


def part_view(payload: Mapping[str, Any] | None, result: IdentificationResult | None = None) -> dict[str, Any]:
    """What the result page leads with, from a stored payload (its envelope, read as a ``PartOutcome``) and its
    typed result.

    kind: "part" (the part is complete: its verdict), "release" (a release of a part in progress: no part
    verdict yet), "plain" (no recipe: a value without a verdict). value, U (kg·m²), k: the number the
    decision rests on and its expanded uncertainty; std: a 1σ when no U exists. part, release: the outcome's.
    """
    o = PartOutcome.from_dict(payload)
    recipe, part, release = o.recipe, o.part, o.release
    made = part or release
    quantity = made.quantity if made is not None else (recipe or {}).get("quantity") or "J"
    out: dict[str, Any] = {"recipe": recipe, "part": part, "release": release, "excluded": [], "reasons": [],
                           "budget": budget_rows(result.uncertainty_budget.get(quantity) if result is not None else None)}
    k = (recipe or {}).get("coverage_factor") or (result.coverage_factor if result is not None else None)
    if part is not None:
        out.update(kind="part", verdict=part.verdict, value=part.value, U=part.U, k=k, quantity=part.quantity,
                   used=len(part.used), releases=part.releases,
                   excluded=[{"release": int(e.get("index", 0)) + 1, "reason": plain_text(e.get("reason") or "")}
                             for e in part.excluded],
                   # the exclusions are listed once (the part's reasons repeat them after "release N:")
                   reasons=[plain_text(r) for r in part.decision.reasons if not str(r).startswith("release ")],
                   zone=part.decision.zone)
    elif release is not None:
        out.update(kind="release", verdict=None, value=release.value, U=release.decision.U, k=k,
                   quantity=release.quantity, index=release.index, of=release.of)
    else:
        U = result.J_U if result is not None else None
        out.update(kind="plain", verdict=None, value=result.J if result is not None else None, U=U,
                   k=k if U else None, quantity="J", std=result.J_std if result is not None else None)
    out["verdict_words"] = VERDICT_WORDS.get(out.get("verdict") or "", "")
    return out


def release_rows(view: Mapping[str, Any], payload: Mapping[str, Any] | None, result: IdentificationResult | None,
                 lookup: Callable[[str], Any] | None = None) -> list[dict[str, Any]]:
    """Each release of the part (index, of, value kg·m², status, flags, seq, uuid): every release of a complete
    part (``view["part"]``; ``lookup(uuid)``: its stored measurement, for its flags), else the one release of the
    payload (``view["release"]``; its typed ``result``: J and flags)."""
    p = payload or {}
    part = view.get("part")
    if part is not None:
        excluded = {e["release"]: e["reason"] for e in view.get("excluded") or ()}
        ids = list(part.measurements)
        out = []
        for i, value in enumerate(part.values, start=1):
            m = lookup(ids[i - 1]) if lookup is not None and i <= len(ids) else None
            out.append({"index": i, "of": part.releases, "value": value,
                        "status": f"excluded: {excluded[i]}" if i in excluded else "used",
                        "flags": list(m.flags) if m is not None else None,
                        "seq": m.seq if m is not None else None, "uuid": ids[i - 1] if i <= len(ids) else None})
        return out
    rel = view.get("release")
    value = rel.value if rel is not None else (result.J if result is not None else None)
    return [{"index": rel.index if rel is not None else 1, "of": rel.of if rel is not None else 1, "value": value,
             "status": f"check {rel.verdict}; the part's verdict is on its last release" if rel is not None
             and rel.verdict else "no recipe",
             "flags": list(result.flags) if result is not None else [], "seq": p.get("seq"), "uuid": p.get("uuid")}]


def band(recipe: Mapping[str, Any] | None, value: float | None, U: float | None, unit: str = SI,
         width: float = 600.0) -> dict[str, Any] | None:
    """The tolerance band drawing (SVG x coordinates in a ``width`` wide box): LSL, nominal, USL, the guard
    band (ISO 14253-1: the zone shrunk by U at each end) and the result's interval value ± U; the limits
    labelled in ``unit`` with the recipe's decimals (``places``), as the value above the band."""
    if not recipe or recipe.get("lower") is None or recipe.get("upper") is None:
        return None
    lsl, usl, nominal = float(recipe["lower"]), float(recipe["upper"]), recipe.get("nominal")
    span = usl - lsl
    lo, hi = lsl - 0.35 * span, usl + 0.35 * span
    u = float(U) if U is not None and math.isfinite(U) else 0.0
    if value is not None and math.isfinite(value):
        lo, hi = min(lo, value - u - 0.05 * span), max(hi, value + u + 0.05 * span)
    pad = 12.0

    def x(v: float) -> float:
        return round(pad + (v - lo) / (hi - lo) * (width - 2 * pad), 1)

    guard = recipe.get("rule", "guard_band") == "guard_band" and 0 < 2 * u < span
    n = places(recipe, unit, U)
    out: dict[str, Any] = {
        "width": width, "lsl": x(lsl), "usl": x(usl), "nominal": x(nominal) if nominal is not None else None,
        "labels": [(x(lsl), "LSL " + inertia(lsl, unit, n)), (x(usl), "USL " + inertia(usl, unit, n))],
        "guard": (x(lsl + u), x(usl - u)) if guard else None, "value": None, "interval": None}
    if value is not None and math.isfinite(value):
        out["value"] = x(value)
        out["interval"] = (x(value - u), x(value + u))
    return out


def shift_start(starts: Sequence[str], now: dt.datetime) -> dt.datetime:
    """The start of the shift ``now`` (local, aware) is in; ``starts``: "HH:MM" local times."""
    best = None
    for days in (0, 1):
        day = (now - dt.timedelta(days=days)).date()
        for hm in starts:
            h, m = (int(t) for t in hm.split(":"))
            t = dt.datetime(day.year, day.month, day.day, h, m, tzinfo=now.tzinfo)
            if t <= now and (best is None or t > best):
                best = t
    return best if best is not None else now.replace(hour=0, minute=0, second=0, microsecond=0)


# --- control charts as SVG -----------------------------------------------------------------------------------------
#: the run rules in words, with the rule's number in the Western Electric handbook (WE) and in Nelson (1984)
RULE_WORDS = {
    "beyond_limits": "a point beyond the 3σ control limits (WE 1, Nelson 1)",
    "run_of_8": "8 points in a row on one side of the centre line (WE 4; Nelson 2 asks for 9)",
    "trend_of_6": "6 points in a row steadily rising or falling (Nelson 3)",
    "2_of_3_beyond_2sigma": "2 of 3 points in a row beyond 2σ on one side (WE 2, Nelson 5)",
    "range_beyond_limits": "a range beyond its control limits: the spread within a part changed",
}


def control_chart(summary: Any, unit: str = SI, width: float = 720.0, height: float = 300.0,
                  names: Sequence[str] = (), places: int | None = None) -> dict[str, Any]:
    """An SPC summary (``measurement.spc.SpcSummary``) as SVG geometry: the points (violations marked), the
    centre line and the control limits, the specification limits when they are near enough not to flatten
    the chart (else named as off the chart), each labelled on the right; the ranges below, theirs marked too.
    ``names``: what each point is called (serial and time), else "part N". Values in ``unit``, written with
    ``places`` decimals (the recipe's: ``places``; None: those that tell the points apart)."""
    s = summary
    f = from_si(1.0, unit) or 1.0
    pts = [float(v) * f for v in s.points]
    lines = [("centre", s.mean * f, "centre"), ("UCL", s.ucl * f, "limit"), ("LCL", s.lcl * f, "limit")]
    width_cl = max((s.ucl - s.lcl) * f, 1e-300)
    off_chart = []
    for name, v in (("USL", s.usl), ("LSL", s.lsl)):
        if v is None:
            continue
        v = v * f
        if s.lcl * f - 2 * width_cl <= v <= s.ucl * f + 2 * width_cl:
            lines.append((name, v, "spec"))
        else:
            off_chart.append(f"{name} {_plain(v, width_cl, places)} {unit} "
                             f"({'above' if v > s.ucl * f else 'below'} the chart)")
    label = [names[i] if i < len(names) and names[i] else f"part {i + 1}" for i in range(len(pts))]
    first = 1 if s.subgroup == 1 else 0  # a moving range starts at the second part
    range_bad = {i + first for i, r in enumerate(s.ranges)
                 if r > s.range_ucl or (s.range_lcl > 0 and r < s.range_lcl)}
    # one entry per point, every rule it breaks (the point beyond the limits is one rule, said once)
    broken: dict[int, list[str]] = {}
    for i, rule in sorted({(v.index, v.rule) for v in s.violations} | {(i, "beyond_limits") for i in s.outside}):
        broken.setdefault(i, []).append(RULE_WORDS.get(rule, rule))
    for i in sorted(range_bad):
        broken.setdefault(i, []).append(RULE_WORDS["range_beyond_limits"])
    bad = {v.index for v in s.violations} | set(s.outside)
    top = _panel(pts, lines, bad, width, height, width_cl, names=label, places=places)
    f_r = [float(r) * f for r in s.ranges]
    rname = {"Xbar-S": "S̄"}.get(s.chart, "R̄")
    r_lines = [(rname, s.range_mean * f, "centre"), ("UCL", s.range_ucl * f, "limit")]
    if s.range_lcl > 0:
        r_lines.append(("LCL", s.range_lcl * f, "limit"))
    bottom = _panel(f_r, r_lines, range_bad, width, height * 0.6, max(s.range_ucl * f, 1e-300), x_offset=first,
                    n_total=len(pts), names=label, floor=0.0, places=places)
    range_name = ("moving range" if s.subgroup == 1 else
                  f"standard deviation (n = {s.subgroup})" if s.chart == "Xbar-S" else f"range (n = {s.subgroup})")
    return {"top": top, "bottom": bottom, "rules": [(label[i], words) for i, words in sorted(broken.items())],
            "off_chart": off_chart, "range_name": range_name}


def run_panel(values: Sequence[float], lines: Sequence[tuple[str, float, str]], width: float = 720.0,
              height: float = 300.0, names: Sequence[str] = (), bad: set[int] | None = None,
              places: int | None = None) -> dict[str, Any]:
    """A run chart's geometry: ``values`` in their order and named horizontal ``lines`` (name, value, kind
    "centre" | "limit" | "spec"), drawn as a control chart's upper panel; in the unit of the values, with
    ``places`` decimals (None: those that tell them apart); ``bad``: the indices of the points marked."""
    ys = list(values) + [v for _, v, _ in lines]
    spread = (max(ys) - min(ys)) if ys else 0.0
    return _panel(values, lines, bad or set(), width, height, spread if spread > 0 else 1.0, names=names,
                  places=places)


def _plain(v: float, spread: float, places: int | None = None) -> str:
    """``v`` with ``places`` decimals (a recipe's), else those that tell values ``spread``/50 apart."""
    if places is not None:
        return signed(number(v, places))
    decimals = max(0, min(12, 1 - int(math.floor(math.log10(spread / 50.0))))) if spread > 0 else 6
    return signed(f"{v:.{decimals}f}" if abs(v) < 1e7 else f"{v:.6g}")


#: px: the rotated axis title's band at a chart's left edge, and the width of one character of a tick label
TITLE_BAND, TICK_CHAR = 20.0, 6.7


def _panel(values: Sequence[float], lines: Sequence[tuple[str, float, str]], bad: set[int], width: float,
           height: float, spread: float, x_offset: int = 0, n_total: int | None = None,
           names: Sequence[str] = (), floor: float | None = None, places: int | None = None) -> dict[str, Any]:
    narrow = width < 500  # a phone's chart: narrower margins, labels as readable
    left, right, top, bottom = (62.0, 122.0, 12.0, 26.0) if narrow else (90.0, 170.0, 12.0, 26.0)
    n = n_total or len(values)
    ys = list(values) + [v for _, v, _ in lines]
    lo, hi = (min(ys), max(ys)) if ys else (0.0, 1.0)
    if hi - lo <= 0:
        lo, hi = lo - 1.0, hi + 1.0
    margin = 0.08 * (hi - lo)
    lo, hi = lo - margin, hi + margin
    if floor is not None:
        lo = max(lo, floor)  # a range is never below zero: neither is its axis
    tick_values = [lo + (hi - lo) * i / 4 for i in range(5)]
    # the ticks in the values' decimals while those tell them apart (a flat series: as many as it takes)
    tick_places = places if places is not None and 10.0 ** -places <= (hi - lo) / 8 else None
    tick_texts = [_plain(v, (hi - lo) * 5, tick_places) for v in tick_values]
    # the axis title's band, then the longest tick label (11 px digits, some 6.7 px wide): never over each other
    left = max(left, TITLE_BAND + TICK_CHAR * max(len(t) for t in tick_texts) + 8.0)

    def X(i: int) -> float:
        return round(left + (i + 0.5) / max(n, 1) * (width - left - right), 1)

    def Y(v: float) -> float:
        return round(top + (hi - v) / (hi - lo) * (height - top - bottom), 1)

    points = [(X(i + x_offset), Y(v), (i + x_offset) in bad,
               names[i + x_offset] if i + x_offset < len(names) else f"part {i + x_offset + 1}",
               _plain(v, spread, places)) for i, v in enumerate(values)]
    drawn = [(name, Y(v), kind, f"{name} {_plain(v, spread, places)}") for name, v, kind in lines]
    # labels at least 13 px apart, in the order of their lines, kept inside the panel
    order = sorted(drawn, key=lambda d: d[1])
    ys_l: list[float] = []
    for _name, y, _kind, _text in order:
        ys_l.append(max(y, ys_l[-1] + 13.0) if ys_l else y)
    overflow = ys_l[-1] - (height - bottom) if ys_l else 0.0
    if overflow > 0:
        ys_l = [max(top, y - overflow) for y in ys_l]
        for i in range(1, len(ys_l)):
            ys_l[i] = max(ys_l[i], ys_l[i - 1] + 13.0)
    labels = [(y + 4, kind, text) for y, (_n, _y, kind, text) in zip(ys_l, order)]
    ticks = [(Y(v), text) for v, text in zip(tick_values, tick_texts)]
    step = max(1, n // (5 if narrow else 10))
    xticks = [(X(i), str(i + 1)) for i in range(0, n, step)]
    return {"width": width, "height": height, "left": left, "right": width - right, "top": top,
            "bottom": height - bottom, "points": points, "lines": drawn, "labels": labels, "yticks": ticks,
            "xticks": xticks,
            "path": " ".join(f"{'M' if k == 0 else 'L'}{x},{y}" for k, (x, y, *_rest) in enumerate(points))}
