"""Step 6, the report's sentences: what the residual holds and what each check found, in words.

Kept apart from the fitting, as lmfit keeps its report apart from its
minimizer: ``describe`` reads the ``Findings`` and fits nothing. The
sentences become the result's ``structure`` (the report's [[Residual]]).
"""

from __future__ import annotations

import math

from .. import flags as F
from ..fit import swing_amplitude
from ..result import LIMIT, SegmentCheck
from ..trace import READING_UNITS
from .discovery import SCREEN_TRUST
from .findings import Findings
from .flags import FOLLOW_LIMIT, Leftover
from .focus import DECLARED
from .measurand import has_law, read_at
from .quantities import omega_at_amplitude
from .rivals import LAW_SIGMA


def _halves(segments: SegmentCheck | None) -> str:
    if segments is None:
        return "the record is too short to fit each half alone: whether the model holds across it is not checked"
    (w1, w2), (s1, s2) = segments.omega_n, segments.omega_n_std
    verdict = ("they disagree: the model lacks something that changes with the amplitude or the time "
               f"(flag halves_disagree); ±{segments.u:.2g} rad/s of model form enters omega_n_u"
               if segments.disagree else "they agree")
    said = (f"the final model fitted to each half of the record (split at {segments.t_split:.3g} s) gives "
            f"ω_n {w1:.6g} ± {s1:.2g} and {w2:.6g} ± {s2:.2g} rad/s ({segments.z:.1f} σ apart): {verdict}")
    if segments.omega_n_free is None:
        return said
    return (f"{said}; the first half without its first half-swing (from {segments.t_free:.3g} s: the release "
            f"may not be a free swing) gives {segments.omega_n_free:.6g} ± {segments.omega_n_std_free:.2g} rad/s, "
            f"and ±{segments.u:.2g} rad/s of model form from the halves enters omega_n_u")


def _guards(found: Findings) -> list[str]:
    """A final fit that had left the optimum, and one that does not follow the swing."""
    out = []
    final, beaten_by, slipped_from = found.final, found.beaten_by, found.slipped_from
    unit = READING_UNITS[found.rig.measures]
    if beaten_by is not None:
        kept = ("refitted from that model's values" if final is not beaten_by else
                f"that model is kept ({', '.join(final.model.effect_names) or 'no effect'}): a refit from its values "
                "did not reach it")
        out.append(
            f"the model {', '.join(slipped_from.model.effect_names)} ended with residual RMS "
            f"{slipped_from.residual_rms:.3g} {unit}, worse than the model it contains "
            f"({', '.join(beaten_by.model.effect_names) or 'no effect'}, {beaten_by.residual_rms:.3g} {unit}) on the same "
            f"samples: its fit had left the optimum; {kept}")
    if not found.follows:
        out.append(
            f"the fit does not follow the swing: its residual RMS {final.residual_rms:.3g} {unit} is "
            f"{100 * found.follow_ratio:.0f} % of the fitted swing's RMS (limit {100 * FOLLOW_LIMIT:.0f} %) and "
            f"{final.residual_rms / found.prep.noise:.0f} × the noise floor; do not use this J (flag fit_not_converged)")
    return out


def _rivals(found: Findings) -> list[str]:
    """The withdrawn effect, the restoring law in a mimicking effect's place, the rivals that enter u."""
    out = []
    w, withdrawn, law = found.omega_n, found.withdrawn, found.law
    if withdrawn is not None:
        head = (f"{', '.join(withdrawn.effects)} lowered BIC by {-withdrawn.d_bic:.1f} but moved ω_n to "
                f"{withdrawn.omega_n:.6g} rad/s ({withdrawn.omega_n - w:+.2g})")
        ws_ = withdrawn.segments
        if withdrawn.undetermined is not None or ws_ is None:
            name, value, std = withdrawn.undetermined or ("", math.nan, math.nan)
            why = (f"and the record does not determine the law it adds ({name} {value:.3g} ± {std:.2g}, "
                   f"{abs(value) / std:.1f} σ from zero, needs {LAW_SIGMA:g}): a restoring law that moves ω_n must "
                   "be a property of the object, not a stand-in for what the model lacks elsewhere")
        else:
            why = (f"and the model with it does not hold across the record (halves {ws_.omega_n[0]:.6g} and "
                   f"{ws_.omega_n[1]:.6g} rad/s, {ws_.z:.1f} σ apart, and not far closer than without it)")
        out.append(f"{head}, {why}: it is not kept, its ω_n is a rival in omega_n_u (flag model_ambiguous)")
    for name, w_law, _, why_law in found.rival_laws:
        out.append(f"{name} was not kept: {why_law}; the releases of this object withdrew it together, and its "
                   f"ω_n here ({w_law:.6g} rad/s, {w_law - w:+.2g}) is a rival in omega_n_u (flag model_ambiguous)")
    if law is not None:
        verdict = ("the data do not separate them: its ω_n enters omega_n_u by its BIC weight"
                   if law.d_bic < found.bic_margin else "the data separate them: the effect stands")
        out.append(
            f"{law.effect} changes how the swing's frequency depends on its amplitude, as a restoring law other than "
            f"the rig's would: fitted in its place, {law.law} (not offered on this rig) gives ω_n {law.omega_n:.6g} rad/s "
            f"({law.omega_n - w:+.2g}) at ΔBIC {law.d_bic:+.1f}; {verdict}")
    for c in found.form.competitors if found.ambiguous else ():
        if c.weight >= 0.05:
            out.append(f"a rival explanation the data do not decisively reject: {c.change} (ΔBIC {c.d_bic:+.1f}, "
                       f"weight {c.weight:.2f}) gives ω_n {c.omega_n:.6g} rad/s ({c.delta:+.2g}); "
                       f"the spread enters omega_n_u (flag model_ambiguous)")
    return out


def _left(left: Leftover) -> list[str]:
    if left.unmodeled:
        what = "; ".join(left.named) if left.named else ("it changes ω_n by more than the fit's σ" if left.changes_answer
                                                         else f"the residual is over {SCREEN_TRUST:g} × the noise floor")
        return [f"left unexplained: no effect of the library accounts for this structure ({what}; "
                "flag unmodeled_residual)"]
    if left.structured:
        return ["the rest is coloured noise: structure beyond the noise model that neither changes ω_n beyond "
                "its σ nor has a shape to name"]
    return []


def _sensor(found: Findings) -> list[str]:
    """The angle's scale fitted from the swing, and a camera view more than oblique."""
    out = []
    w, ws = found.omega_n, found.omega_n_std
    if found.nominal is not None:
        names, w_nom = found.nominal
        advice = ("a gyro read about an axis at φ to the swing's reads cos φ of its rate: read the gyro's axes together "
                  "(moi then takes the swing's own direction) before calibrating its scale"
                  if found.rig.measures == "rate" else "calibrate the sensor's scale")
        out.append(f"the {found.rig.measures}'s scale was fitted from the swing ({', '.join(names)}): with the sensor at "
                   f"its nominal scale ω_n would read {w_nom:.6g} rad/s ({(w_nom - w) / ws:+.1f} σ, "
                   f"{100 * (w_nom - w) / w:+.2f} %); {advice} (flag sensor_scale_fitted)")
    if F.CAMERA_PERSPECTIVE in found.trace.flags:
        pattern = float((found.view or {}).get("distance_pattern", float("nan")))
        out.append(f"the camera's view was more than oblique: the two markers' distance changed with the angle "
                   f"by up to {100 * pattern:.1f} % after the oblique view was removed (perspective, or a "
                   f"position-dependent tracker bias); the angle keeps an error of that kind and part of the "
                   f"residual may be it (flag camera_perspective)")
    return out


def _focus(found: Findings) -> list[str]:
    """Which model the headline ω_n is read from, where the declared and the discovered one were weighed."""
    head = found.headline
    if head.mse is None:
        return []
    mse_d, mse_f = (math.sqrt(m) for m in head.mse)
    w_d, w_f = read_at(found.base, head.at)[0], read_at(found.final, head.at)[0]
    if head.chosen == DECLARED:
        return [f"ω_n is read from the declared model ({', '.join(head.effects)}), {w_d:.6g} rad/s: its ω_n is the more "
                f"accurate (estimated root mean squared error {mse_d:.2g} rad/s, its halves and its distance to the "
                f"discovered model's included, against {mse_f:.2g}); the discovered model's ω_n {w_f:.6g} rad/s "
                f"({w_f - w_d:+.2g}) is its rival in omega_n_u"]
    return [f"the declared model's ω_n {w_d:.6g} rad/s would be the less accurate (estimated root mean squared "
            f"error {mse_d:.2g} rad/s against the discovered model's {mse_f:.2g}): ω_n is the discovered model's"]


def _measurand(found: Findings) -> list[str]:
    """Where ω_n is read (``measurand``), and where a restoring law is kept the swing's own frequency beside it."""
    read = found.read_at
    if not has_law(found.final):
        return []  # ω is the same at every amplitude the model knows
    out = [read.describe()] if read.basis != LIMIT else []
    if found.headline.chosen == DECLARED:
        return out
    amplitude = swing_amplitude(found.final)
    at = omega_at_amplitude(found.final, amplitude)
    if at is None:
        return out
    w = read_at(found.final, read.amplitude)[0]
    laws = ", ".join(e.name for e in found.final.model.dynamic if e.role == "stiffness")
    if read.amplitude <= 0:
        return [f"ω_n is the small-swing limit of the restoring law ({laws} kept): at the record's largest swing, "
                f"{amplitude:.3g} rad, the law gives ω {at[0]:.6g} ± {at[1]:.2g} rad/s ({100 * (at[0] - w) / w:+.2f} %)"
                ] + out
    return out + [f"at the record's largest swing, {amplitude:.3g} rad, the law ({laws} kept) gives ω {at[0]:.6g} ± "
                  f"{at[1]:.2g} rad/s ({100 * (at[0] - w) / w:+.2f} %)"]


def describe(found: Findings, left: Leftover) -> tuple[str, ...]:
    """The report's sentences on the residual and every check, in the order a reader needs them."""
    return tuple(found.diag.describe(READING_UNITS[found.rig.measures]) + [_halves(found.segments)] + _guards(found) + _rivals(found) + _left(left)
                 + _sensor(found) + _focus(found) + _measurand(found))
