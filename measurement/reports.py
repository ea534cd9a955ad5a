"""The plain-text reports a technician reads, apart from the results they describe (as lmfit keeps its
``fit_report`` in ``printfuncs``): one release (``result_report``), several releases of one object
(``joint_report``), an inertia tensor (``tensor_report``). Each report is a list of named sections.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

from . import flags as F
from .flags import FIT_NOT_CONVERGED
from .joint import CONSISTENT_P, OWN_PAIR_Z, JointResult
from .result import LIMIT, IdentificationResult, Quantity, _num
from .tensor import COMPONENTS, TensorResult
from .trace import READING_UNITS
from .uncertainty import Budget

if TYPE_CHECKING:
    from .reproducibility import Reproducibility

#: combined u of ω_n over the fit's σ beyond which the report states ω_n with u on a line of its own
WIDER = 2.0

_NO_J = ("    J            = n/a: the rig gives no stiffness (torsion), mass·com_distance (compound) or mass "
         "(bifilar, trifilar)")


def budget_table(b: Budget) -> list[str]:
    """A budget (``measurement.uncertainty.Budget``) as the report's table."""
    out = [f"    {'source':<32}{'value':>12}{'u':>10}  {'unit':<8}{'c':>10}{'c·u':>10}{'share':>8}"]
    for ln in b.lines:
        note = f"  ({ln.note})" if ln.note else ""
        value = ln.value if _num(ln.value) is not None else float("nan")
        c = ln.sensitivity if _num(ln.sensitivity) is not None else float("nan")
        out.append(f"    {ln.source[:32]:<32}{value:>12.6g}{ln.std:>10.2g}  {ln.unit:<8}{c:>10.3g}"
                   f"{ln.contribution:>10.2g}{100 * ln.share:>7.1f}%{note}")
    for r in b.correlations:
        out.append(f"    correlation r({r['a']}, {r['b']}) = {r['r']:+.4f}: {100 * b.correlation_share:+.1f} % of u²")
    dof = "∞" if _num(b.dof) is None or b.dof >= 1e6 else f"{b.dof:.0f}"
    rel = f" ({100 * b.U / abs(b.value):.3g} %)" if b.value else ""
    out.append(f"    u = {b.u:.3g} {b.unit}, ν_eff = {dof}, k = {b.coverage_factor:.2f}, "
               f"U = {b.U:.3g} {b.unit}{rel}")
    return out


def reproducibility_line(r: Reproducibility | None) -> str:
    """The report's line on the scatter between releases, which one record cannot see."""
    if r is None or r.relative is None:
        return ("    reproducibility: not known (remounting, the pivot settling, a hand-held sensor): not in u; "
                "measure ≥ 3 releases, whose joint identification carries their scatter")
    if not r.known:
        return f"    reproducibility: {r.note()}"
    return (f"    reproducibility: ±{100 * r.relative:.2g} % of ω_n between releases ({r.note()}, ν = {r.dof:.0f}): in u")


# -- one release -----------------------------------------------------------------------------------

def result_report(r: IdentificationResult) -> str:
    """A plain-text report of one release for the technician (lmfit ``fit_report`` style)."""
    L = _heading(r) + _inertias(r) + _frequency(r) + _uncertainty(r) + _parameters(r) + _model(r)
    L += _before_after(r) + _discovery(r) + ["[[Residual]]"] + [f"    {line}" for line in r.structure]
    L += _acquisition(r.acquisition) + [F.report_line(r.flags)]
    return "\n".join(L)


def _heading(r: IdentificationResult) -> list[str]:
    s = r.statistics
    converged = ("no (flag fit_not_converged: do not use this J)" if FIT_NOT_CONVERGED in r.flags
                 else f"{s.get('success')}")
    return [f"[[Identification]] {r.source}  ({r.rig_kind} rig)",
            f"    samples {s.get('n')}, window {r.window.get('t_start', 0):.3f}–{r.window.get('t_stop', 0):.3f} s,"
            f" {s.get('nfev')} simulations, converged: " + converged,
            "[[Result]]"]


def _inertias(r: IdentificationResult) -> list[str]:
    def expanded(measurand: str) -> str:
        b = r.uncertainty_budget.get(measurand)
        return "" if b is None else f"; U = {b.U:.2g} kg·m² (k = {b.coverage_factor:.3g}, budget below)"

    L = [f"    J            = {Quantity(r.J, r.J_std, 'kg·m²')}{expanded('J')}" if r.J is not None else _NO_J]
    if r.J_object is not None:
        L.append(f"    J_object     = {Quantity(r.J_object, r.J_object_std, 'kg·m²')}  (J − tare)"
                 f"{expanded('J_object')}")
    if r.J_object_axis is not None:
        L.append(f"    J_object_axis= {Quantity(r.J_object_axis, r.J_object_axis_std, 'kg·m²')}  (own axis, J_D − m·L²)"
                 f"{expanded('J_object_axis')}")
    return L


def _frequency(r: IdentificationResult) -> list[str]:
    cal = f"; the camera view's calibration adds ±{r.omega_n_std_calibration:.2g}" if r.omega_n_std_calibration else ""
    L = [f"    omega_n      = {Quantity(r.omega_n, r.omega_n_std, 'rad/s')}"
         f"  (f_n = {r.omega_n / (2 * math.pi):.6g} Hz{cal})"]
    if r.periods is not None:
        L.extend(r.periods.lines())
    if r.omega_n_read_at.basis != LIMIT and r.stiffness:  # a fitted law: ω depends on where it is read
        L.append(f"    ω_n read at  = a swing of {r.omega_n_read_at.amplitude:.3g} rad ({r.omega_n_read_at.basis}; "
                 "on a torsion rig J = k/ω² takes ω where k was calibrated)")
    if r.omega_n_from != "discovered":
        L.append(f"    ω_n from     = the {r.omega_n_from} model ({', '.join(r.omega_n_effects)}): its ω_n is "
                 "the more accurate (the discovered model's is a rival in u)")
    if r.omega_n_u is not None and r.omega_n_u > WIDER * r.omega_n_std:
        # the fit's σ alone would read as a confident number where the model's form is not settled
        L.append(f"    ω_n ± u      = {Quantity(r.omega_n, r.omega_n_u, 'rad/s')} (combined u: the fit's σ "
                 f"is {r.omega_n_u / r.omega_n_std:.3g} times narrower than what the record supports)")
    if r.omega_n_std_model:
        ju = f"; J ± {r.J_u:.2g} kg·m²" if r.J_u is not None else ""
        L.append(f"    model form   = ±{r.omega_n_std_model:.2g} rad/s (halves of the record, rival models)"
                 f" → combined u: ω_n ± {r.omega_n_u:.2g} rad/s{ju}")
    L.append(reproducibility_line(r.reproducibility))
    return L


def _uncertainty(r: IdentificationResult) -> list[str]:
    L: list[str] = []
    for measurand, budget in r.uncertainty_budget.items():
        L.append(f"[[Uncertainty budget]] {measurand} (GUM; J_std above is the fit's 1σ alone)")
        L.extend(budget_table(budget))
    return L


def _parameters(r: IdentificationResult) -> list[str]:
    L = [f"    damping ratio= {Quantity(r.damping_ratio, r.damping_ratio_std, '')}"
         f" (equivalent viscous, at {r.reference_amplitude:.4g} rad)"]
    L += _effect_lines(r.damping, r.stiffness, r.sensor)
    L.append(f"    offset       = {r.offset}")
    return L


def _effect_lines(*groups: dict[str, dict[str, Quantity]]) -> list[str]:
    return [f"    {eff}.{name:<10} = {q}" for group in groups for eff, params in group.items()
            for name, q in params.items() if q.value is not None]


def _model(r: IdentificationResult) -> list[str]:
    L = ["[[Model]]",
         f"    declared : {', '.join(r.declared_effects) or '(none)'}",
         f"    final    : {', '.join(r.effects) or '(none)'}",
         f"    added    : {', '.join(r.added_effects) or '(none)'}"]
    if r.sensor_calibrated:
        L.append("    sensor   : calibrated (its scale is known: effects that fit it, gain and view, not offered)")
    return L


def _before_after(r: IdentificationResult) -> list[str]:
    b = r.baseline
    jb = f"{b.J:.7g}" if b.J is not None else "n/a"
    ja = f"{r.J:.7g}" if r.J is not None else "n/a"
    unit = READING_UNITS.get(r.measures, "rad")
    ratio = r.residual_rms / r.noise_floor if r.noise_floor else float("nan")
    return ["[[Before / after]]",
            f"    {'':14}{'declared':>16}{'final':>16}",
            f"    {'J [kg·m²]':14}{jb:>16}{ja:>16}",
            f"    {'omega_n [rad/s]':14}{b.omega_n:>15.7g}{r.omega_n:>16.7g}",
            f"    {f'residual [{unit}]':14}{b.residual_rms:>16.4g}{r.residual_rms:>16.4g}",
            f"    {'BIC':14}{b.bic:>16.1f}{r.statistics.get('bic', float('nan')):>16.1f}",
            f"    noise floor {r.noise_floor:.3g} {unit}; residual/noise {ratio:.3g};"
            f" error reduction {100 * (r.error_reduction or 0):.1f} %"]


def _discovery(r: IdentificationResult) -> list[str]:
    if not r.steps:
        return []
    L = ["[[Discovery]]"]
    for st in r.steps:
        tried = ", ".join(f"{k} ΔBIC {v['bic'] - st.bic_before:+.1f}" for k, v in st.candidates.items())
        if st.chosen:
            L.append(f"    round {st.round}: added {st.chosen} — {st.reason}")
            if st.evidence:
                L.append(f"        evidence: {st.evidence}")
        else:
            L.append(f"    round {st.round}: nothing added — {st.reason}")
        if tried:
            L.append(f"        tried: {tried}")
    return L


def _acquisition(acquisition: dict[str, Any]) -> list[str]:
    if not acquisition:
        return []
    L = ["[[Acquisition]]"]

    def walk(prefix: str, value: Any) -> None:
        if isinstance(value, dict):
            for k, v in value.items():
                walk(f"{prefix}.{k}" if prefix else str(k), v)
        elif isinstance(value, float):
            L.append(f"    {prefix} = {value:.6g}")
        else:
            L.append(f"    {prefix} = {value}")

    walk("", acquisition)
    return L


# -- several releases of one object ----------------------------------------------------------------

def joint_report(j: JointResult) -> str:
    """A plain-text report of a joint identification: the releases, the shared result, their consistency."""
    L = _releases(j) + ["[[Result]]"] + _joint_inertia(j) + _joint_frequency(j) + _shared_laws(j)
    L += _effect_lines(j.damping, j.stiffness) + _consistency(j) + [F.report_line(j.flags)]
    return "\n".join(L)


def _releases(j: JointResult) -> list[str]:
    c = j.consistency
    L = [f"[[Joint identification]] {len(j.releases)} releases of one object ({j.rig_kind} rig)",
         f"    shared effects: {', '.join(j.effects) or '(none)'}; per release: initial state, zero offset, sensor terms",
         "[[Releases]]  each alone: its own model (ω_n ± combined u), and the shared model (ω_n ± u, z against the joint)",
         f"    {'source':<34}{'from–to [s]':>16}{'amplitude':>10}{'T there [s]':>12}{'own ω_n':>12}{'u':>9}{'shared ω_n':>12}{'u':>9}"
         f"{'z':>7}  own effects / flags"]
    for r, w, u, z in zip(j.releases, c["omega_n"], c["u"], c["z"]):
        uo = r.omega_n_u if r.omega_n_u is not None else r.omega_n_std
        name = r.source if len(r.source) <= 33 else "…" + r.source[-32:]
        span = f"{r.window.get('t_start', math.nan):.2f}–{r.window.get('t_stop', math.nan):.2f}"
        period = r.periods.at_amplitude if r.periods is not None else math.nan
        L.append(f"    {name:<34}{span:>16}{r.reference_amplitude:>10.3g}{period:>12.6g}{r.omega_n:>12.7g}{uo:>9.2g}{w:>12.7g}{u:>9.2g}{z:>+7.1f}  "
                 f"{', '.join(r.effects)}" + (f" / {', '.join(r.flags)}" if r.flags else ""))
    return L


def _joint_inertia(j: JointResult) -> list[str]:
    if j.J is None:
        return [_NO_J]
    L = [f"    J            = {j.J:.7g} kg·m², σ {j.J_std:.2g}, combined u {j.J_u:.2g} kg·m²"
         " (the releases' ω_n alone)"]
    for measurand, b in j.uncertainty_budget.items():
        L.append(f"[[Uncertainty budget]] {measurand} (GUM: the joint ω_n and the rig's constants)")
        L.extend(budget_table(b))
    return L


def _joint_frequency(j: JointResult) -> list[str]:
    jf = j.consistency["joint_fit"]
    L = [f"    omega_n      = {j.omega_n:.7g} rad/s, σ {j.omega_n_std:.2g}, combined u {j.omega_n_u:.2g} rad/s"
         " (the releases weighted by their whole uncertainty)",
         f"    period       = {2 * math.pi / j.omega_n:.6g} ± {2 * math.pi * j.omega_n_u / j.omega_n**2:.2g} s "
         "small-swing (2π/ω_n; T there: each release's at its largest swing)",
         f"    joint fit    : ω_n {jf['omega_n']:.7g} ± {jf['omega_n_std']:.2g} rad/s (all samples, the laws below shared)"]
    if jf.get("apart"):
        L.append(f"    the joint fit and the releases' value are {jf['z']:.1f} σ apart: the shared laws do not hold over "
                 f"the releases' amplitudes; the distance enters u (flag model_ambiguous)")
    return L


def _shared_laws(j: JointResult) -> list[str]:
    c = j.consistency
    if len(c.get("models", ())) <= 1:
        return []
    L = ["    shared laws weighed by all the releases together (joint BIC under each release's noise model):"]
    for m in c["models"]:
        what = ", ".join(m["effects"]) or "(none)"
        what += f" (no {', '.join(m['without'])})" if m["without"] else ""
        L.append(f"      {what:<40} ΔBIC {m['d_bic']:+9.1f}  weight {m['weight']:.2f}  "
                 f"joint-fit ω_n {m['omega_n']:.7g} ± {m['omega_n_std']:.2g}" + ("  (kept)" if m["chosen"] else ""))
    if c.get("not_held"):
        L.append(f"    the laws of least BIC do not hold across {', '.join(c['not_held'])} as the releases' own "
                 "models did (the halves disagree more): the first set is kept, and the distance of the two "
                 "readings enters u")
    if c["u_models"] > j.omega_n_std:
        L.append(f"    the releases do not separate these laws: their spread {c['u_models']:.2g} rad/s enters u "
                 "(flag model_ambiguous)")
    return L


def _consistency(j: JointResult) -> list[str]:
    c = j.consistency
    L = ["[[Consistency]]",
         f"    χ² {c['chi2']:.2f} on {c['dof']} (p = {c['p']:.2g}); largest deviation {c['largest_z']:+.1f} σ "
         f"({c['largest_release']}); largest pairwise difference {c['pairwise_max']:.1f} σ",
         "    " + ("the releases agree with one ω_n within their uncertainties" if c["p"] >= CONSISTENT_P else
                  f"the releases disagree beyond their uncertainties (flag releases_disagree): the joint σ is "
                  f"scaled by the Birge ratio {c['birge_ratio']:.2f}; {c['largest_release']} departs most")]
    if c["own_pairwise_max"] > OWN_PAIR_Z:
        a, b = c["own_pairwise_releases"]
        L.append(f"    as each release reports it alone, {a} and {b} are {c['own_pairwise_max']:.1f} u apart "
                 f"(more than {OWN_PAIR_Z:g}: flag releases_disagree)")
    return L


# -- an inertia tensor -----------------------------------------------------------------------------

def tensor_report(t: TensorResult) -> str:
    """A plain-text report of an inertia tensor: its components, principal axes and the orientations."""
    L = [f"[[Inertia tensor]] {t.part}  (about the centre of mass, part frame; products of inertia "
         f"{t.poi_convention}: Ixy = {'−' if t.poi_convention == 'negative' else '+'}∫xy dm)"]
    L += [f"    {c} = {t.components[c]:.7g} ± {t.U[c]:.2g} kg·m²  (U, k = {t.coverage_factor:g})" for c in COMPONENTS]
    L.append("    matrix T (nᵀ·T·n = inertia about n), kg·m²:")
    L += ["        [" + "  ".join(f"{v:+.6e}" for v in row) + "]" for row in t.tensor]
    L.append("[[Principal]]")
    for lam, U, ax, ang in zip(t.principal_moments, t.principal_moments_U, t.principal_axes, t.principal_axes_U_deg):
        L.append(f"    I = {lam:.7g} ± {U:.2g} kg·m²  axis [{ax[0]:+.4f}, {ax[1]:+.4f}, {ax[2]:+.4f}] ± {ang:.2g}°")
    L += _orientations(t) + [F.report_line(t.flags)] + [f"    {f}: {why}" for f, why in t.reasons.items()]
    return "\n".join(L)


def _orientations(t: TensorResult) -> list[str]:
    L = ["[[Orientations]]",
         f"    {'name':8}{'axis':>26}{'J axis':>14}{'−m·d⊥²':>12}{'J cm':>14}{'± u':>10}{'nᵀTn':>14}{'z':>7}"]
    for o in t.orientations:
        axis = "[" + ", ".join(f"{v:+.3f}" for v in o["axis"]) + "]"
        if o.get("excluded"):
            L.append(f"    {o['name']:8}{axis:>26}   excluded: {o['excluded']}")
            continue
        z = o.get("normalised_residual")
        L.append(f"    {o['name']:8}{axis:>26}{o['J_axis']:>14.6g}{-o['parallel_axis'] or 0.0:>12.3g}{o['J']:>14.6g}"
                 f"{o['u']:>10.2g}{o['fitted']:>14.6g}{'' if z is None else f'{z:+.2f}':>7}")
    if t.dof:
        L.append(f"    χ² = {t.chi2:.3g} for {t.dof} dof (99 % point {t.chi2_limit:.3g}); plan condition "
                 f"number {t.condition_number:.3g}")
    else:
        L.append(f"    6 orientations determine the 6 components exactly: nothing checks them (a plan of more axes "
                 f"does); plan condition number {t.condition_number:.3g}")
    return L
