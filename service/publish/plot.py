"""The picture of an identification: trace and fit, then both residuals one above the other."""

from __future__ import annotations

import io
import os
from typing import TYPE_CHECKING, BinaryIO

import numpy as np

from measurement.result import IdentificationResult
from measurement.trace import READING_UNITS

if TYPE_CHECKING:
    from matplotlib.figure import Figure

#: the picture formats a plot may be written in (by the file name's extension)
PLOT_FORMATS = ("png", "svg", "pdf")


def plot_result(result: IdentificationResult, path: str | os.PathLike | BinaryIO, *, dpi: int = 110,
                fmt: str = "png", unit: str = "kg·m²", source: str | None = None) -> None:
    """Draw the result into ``path`` (a file name or a binary file object) as ``fmt`` (png, svg or pdf); the title
    names ``source`` (default: the trace's own, e.g. its file) and gives J in ``unit``."""
    figure(result, unit=unit, source=source).savefig(path, dpi=dpi, format=fmt)


def reading_label(result: IdentificationResult) -> tuple[str, str]:
    """(what the sensor read, its unit): ("angle", "rad"), or ("rate", "rad/s") for a gyro, whose trace, fit
    and residuals are rates."""
    return result.measures, READING_UNITS[result.measures]


def figure(result: IdentificationResult, *, unit: str = "kg·m²", source: str | None = None) -> Figure:
    """The picture of ``result`` as a matplotlib Figure: the trace and the final model's fit above, the declared
    and the final model's residuals below, each axis labelled with what the sensor read."""
    # a Figure without pyplot: no global state, so the daemon's plot worker thread may draw too
    from matplotlib.figure import Figure

    from measurement.units import from_si

    from .quality import inertia, number

    reading, ru = reading_label(result)
    a = result.arrays
    t, y = a["t"], a["angle"]  # the arrays' "angle" is the reading, a rate on a gyro
    fig = Figure(figsize=(10, 8), layout="constrained")
    axes = fig.subplots(3, 1, sharex=True, gridspec_kw={"height_ratios": [2.2, 1, 1]})
    ax = axes[0]
    ax.plot(a["trace_t"], a["trace_angle"], color="0.75", lw=0.8, label="trace (all samples)")
    ax.plot(t, y, ".", ms=1.5, color="k", label="fitted samples")
    ax.plot(t, a["fitted"], color="tab:red", lw=0.9, label=f"final model: {', '.join(result.effects) or 'undamped'}")
    title = f"{source or os.path.basename(result.source)} — "
    if result.J is not None and from_si(result.J, unit) is not None:
        title += f"J = {inertia(result.J, unit)} ± {inertia(result.J_std, unit, '.2g')} (1σ)"
    else:
        title += "J n/a (rig lacks k or m·S)"
    title += f", ω_n = {number(result.omega_n, '.6g')} rad/s"
    ax.set_title(title)
    ax.set_ylabel(f"{reading} [{ru}]")
    ax.legend(loc="upper right", fontsize=8)
    b = result.baseline
    for ax, res, label in (
        (axes[1], a["baseline_residual"], f"declared ({', '.join(b.effects) or 'none'}): RMS {b.residual_rms:.3g} {ru}"),
        (axes[2], a["residual"], f"final ({', '.join(result.effects) or 'none'}): RMS {result.residual_rms:.3g} {ru}"),
    ):
        ax.plot(t, res, lw=0.6, color="tab:blue")
        ax.axhspan(-result.noise_floor, result.noise_floor, color="tab:green", alpha=0.2,
                   label=f"±noise floor {result.noise_floor:.2g} {ru}")
        ax.set_ylabel(f"residual [{ru}]")
        ax.set_title(label, fontsize=9, loc="left")
        ax.legend(loc="upper right", fontsize=8)
        lim = float(np.max(np.abs(res))) * 1.1 if res.size else 1.0
        ax.set_ylim(-lim, lim)
    axes[2].set_xlabel("t [s]")
    if result.flags:
        axes[2].text(0.01, 0.03, "flags: " + ", ".join(result.flags), transform=axes[2].transAxes, fontsize=8, color="tab:red")
    return fig


def render_png(result: IdentificationResult, unit: str = "kg·m²", source: str | None = None, *, dpi: int = 80) -> bytes:
    """The picture of ``result`` as PNG bytes (what the result store keeps with the measurement); J in ``unit``,
    the title naming ``source``."""
    return render(result, "png", dpi=dpi, unit=unit, source=source)


def render(result: IdentificationResult, fmt: str, *, dpi: int = 110, unit: str = "kg·m²",
           source: str | None = None) -> bytes:
    """The picture of ``result`` as ``fmt`` (png, svg, pdf) bytes."""
    buf = io.BytesIO()
    plot_result(result, buf, dpi=dpi, fmt=fmt, unit=unit, source=source)
    return buf.getvalue()


def plot_control_chart(summary, path: str | os.PathLike, title: str = "", unit: str = "kg·m²") -> None:
    """The control chart of a ``measurement.spc.SpcSummary``: points with centre, control and
    specification limits above (points outside or breaking a run rule in red), ranges below."""
    from matplotlib.figure import Figure

    s = summary
    x = np.arange(1, s.n_points + 1)
    fig = Figure(figsize=(10, 6.5), layout="constrained")
    ax, axr = fig.subplots(2, 1, sharex=True, gridspec_kw={"height_ratios": [2, 1]})
    ax.plot(x, s.points, "o-", color="tab:blue", ms=4, lw=0.8, label="part value" if s.subgroup == 1
            else f"subgroup mean (n = {s.subgroup})")
    flagged = sorted({v.index for v in s.violations})
    if flagged:
        ax.plot(x[flagged], np.asarray(s.points)[flagged], "o", color="tab:red", ms=7, label="outside / run rule")
    ax.axhline(s.mean, color="k", lw=1, label=f"centre {s.mean:.6g}")
    labels = [(s.ucl, "UCL", "tab:red"), (s.lcl, "LCL", "tab:red")]
    for v in (s.ucl, s.lcl):
        ax.axhline(v, color="tab:red", ls="--", lw=1)
    for v, name in ((s.usl, "USL"), (s.lsl, "LSL")):
        if v is not None:
            ax.axhline(v, color="tab:orange", ls=":", lw=1.2)
            labels.append((v, name, "tab:orange"))
    # the limits' labels right of the plot, moved apart where their lines lie close (they overlapped)
    ax.set_xlim(x[0] - 0.5, x[-1] + 0.5)
    lo, hi = ax.get_ylim()
    placed: list[float] = []
    for v, name, colour in sorted(labels, key=lambda t: t[0]):
        frac = (v - lo) / (hi - lo) if hi > lo else 0.5
        frac = max(frac, placed[-1] + 0.06) if placed else frac
        placed.append(frac)
        ax.annotate(f"{name} {v:.6g}", xy=(1.0, (v - lo) / (hi - lo) if hi > lo else 0.5), xycoords="axes fraction",
                    xytext=(1.01, frac), textcoords="axes fraction", va="center", fontsize=8, color=colour,
                    arrowprops={"arrowstyle": "-", "color": colour, "lw": 0.5})
    cap = f"Cp {s.cp:.3g}, Cpk {s.cpk:.3g}" if s.cp is not None and s.cpk is not None else "Cp n/a"
    ax.set_title(f"{title}  {s.chart}: {s.n_points} points, σ within {s.sigma_within:.3g} {unit}, {cap}".strip())
    ax.set_ylabel(unit)
    ax.legend(loc="upper left", fontsize=8)
    xr = x[1:] if s.subgroup == 1 else x
    axr.plot(xr, s.ranges, "o-", color="tab:gray", ms=3, lw=0.8)
    axr.axhline(s.range_mean, color="k", lw=1)
    axr.axhline(s.range_ucl, color="tab:red", ls="--", lw=1)
    if s.range_lcl > 0:
        axr.axhline(s.range_lcl, color="tab:red", ls="--", lw=1)
    axr.set_ylabel("moving range" if s.subgroup == 1 else "range")
    axr.set_xlabel("part")
    fig.savefig(path, dpi=100, format="png")


def render_tensor_png(result, *, dpi: int = 100) -> bytes:
    """The picture of a ``measurement.tensor.TensorResult`` as PNG bytes: each orientation's inertia about
    the centre of mass (with its U) against the tensor's nᵀ·T·n, and the normalised residuals below."""
    from matplotlib.figure import Figure

    rows = result.orientations
    x = np.arange(len(rows))
    names = [r["name"] for r in rows]
    used = [i for i, r in enumerate(rows) if "excluded" not in r]
    k = result.coverage_factor
    fig = Figure(figsize=(max(6.0, 0.8 * len(rows) + 2), 6.5), layout="constrained")
    ax, axr = fig.subplots(2, 1, sharex=True, gridspec_kw={"height_ratios": [2, 1]})
    ax.errorbar(x[used], [rows[i]["J"] for i in used], yerr=[k * rows[i]["u"] for i in used], fmt="o", color="k",
                ms=4, capsize=3, label=f"measured, moved to the centre of mass (± U, k = {k:g})")
    ax.plot(x, [r["fitted"] for r in rows], "_", color="tab:red", ms=18, mew=2, label="tensor: nᵀ·T·n")
    out = [i for i in range(len(rows)) if i not in used]
    if out:
        ax.plot(x[out], [rows[i]["fitted"] for i in out], "x", color="tab:gray", ms=8, label="excluded")
    lam = ", ".join(f"{v:.5g}" for v in result.principal_moments)
    check = f"χ² {result.chi2:.3g} for {result.dof} dof" if result.dof else "6 axes: no check"
    ax.set_title(f"{result.part}: principal moments {lam} kg·m²; {check}", fontsize=9)
    ax.set_ylabel("inertia about the axis [kg·m²]")
    ax.legend(loc="best", fontsize=8)
    z = [rows[i]["normalised_residual"] for i in used]
    axr.bar(x[used], [0.0 if v is None else v for v in z], color="tab:blue")
    axr.axhline(0, color="k", lw=0.8)
    for s in (-3, 3):
        axr.axhline(s, color="tab:red", ls="--", lw=0.8)
    axr.set_ylabel("normalised residual")
    axr.set_xticks(x, names)
    axr.set_xlabel("orientation")
    if result.flags:
        axr.text(0.01, 0.03, "flags: " + ", ".join(result.flags), transform=axr.transAxes, fontsize=8, color="tab:red")
    buf = io.BytesIO()
    fig.savefig(buf, dpi=dpi, format="png")
    return buf.getvalue()
