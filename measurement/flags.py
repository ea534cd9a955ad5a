"""Quality flags: every flag a result can carry, with its meaning, in one table.

A flag is a short lower-case name in ``IdentificationResult.flags`` (and so in
the JSON, the MQTT payload and, as a bit, in the Modbus register ``flags``).
Whoever raises a flag uses the constant below; ``FLAG_BITS`` gives every
flag of this table its bit in the published bit field (the payload's
``flag_bits``, the Modbus registers; a test fails when one is missing).

Each flag is graded by what its condition does to the answer (``GRADES``):

* **warning**: the condition may move ω_n or J by more than the uncertainty
  the result states (the fit did not follow the swing, the calibration is
  stale, the angle's scale rests on the swing itself, the releases of one
  object lie beyond each other's u). A recipe may treat it as INVALID.
* **information**: the condition describes the record or its residual, and
  whatever it does to ω_n is already in the stated u (the record's halves
  and rival models are in the model-form term, a coloured residual in the
  noise model, glitches left out or down-weighted). It is kept in the result
  and the report, and is never a reason to invalidate a part by default: a
  flag that fires on most real records and invalidates them teaches the
  operator to ignore flags.
"""

from __future__ import annotations

from typing import Iterable

# -- identification ---------------------------------------------------------------
UNMODELED_RESIDUAL = "unmodeled_residual"
OUTLIERS_REMOVED = "outliers_removed"
PARAMETER_AT_BOUND = "parameter_at_bound"
FIT_NOT_CONVERGED = "fit_not_converged"
CORRELATED_RESIDUAL = "correlated_residual"
OUTLIERS_DOWNWEIGHTED = "outliers_downweighted"
WINDOW_CUT_AT_GAP = "window_cut_at_gap"
ANGLE_UNWRAPPED = "angle_unwrapped"
SENSOR_SCALE_FITTED = "sensor_scale_fitted"
HALVES_DISAGREE = "halves_disagree"
MODEL_AMBIGUOUS = "model_ambiguous"
RELEASES_DISAGREE = "releases_disagree"
# -- acquisition --------------------------------------------------------------------
ENCODER_ERRORS = "encoder_errors"
CAMERA_POSE = "camera_pose"
MARKER_LOST = "marker_lost"
DROPPED_FRAMES = "dropped_frames"
CORRUPT_FRAME = "corrupt_frame"
CAMERA_PERSPECTIVE = "camera_perspective"
CAPTURE_SLOWED = "capture_slowed"
# -- the rig ---------------------------------------------------------------------------
CALIBRATION_DUE = "calibration_due"
NEGATIVE_INERTIA = "negative_inertia"
# -- the inertia tensor of a multi-orientation set ----------------------------------------------
TENSOR_INCONSISTENT = "tensor_inconsistent"
TENSOR_UNPHYSICAL = "tensor_unphysical"
ORIENTATION_EXCLUDED = "orientation_excluded"

#: flag → what it tells the user (the Modbus map and the docs print these)
FLAGS: dict[str, str] = {
    UNMODELED_RESIDUAL: "the residual holds structure no library effect explains, and it matters: it changes ω_n "
                        "by more than the fit's σ (the record's halves disagree), or it has a shape the report names "
                        "(an envelope that decays otherwise than the model's, a spectral line, a trend, unequal "
                        "half-swings), or it stands over 4 × the noise floor; coloured noise alone does not raise it",
    OUTLIERS_REMOVED: "isolated glitch samples were left out of the fit (count in window.n_outliers)",
    PARAMETER_AT_BOUND: "an effect's parameter sits at its physical bound (e.g. a damping of zero)",
    FIT_NOT_CONVERGED: "the least-squares fit stopped before converging, or ended where the model does not follow "
                       "the swing (a residual over a third of the swing's RMS, far above the noise floor): do not "
                       "use this J",
    CORRELATED_RESIDUAL: "the residual is coloured; uncertainties and BIC use the fitted noise model",
    OUTLIERS_DOWNWEIGHTED: "the robust loss gave samples far off the model a reduced weight (count in window.n_downweighted)",
    WINDOW_CUT_AT_GAP: "the fit window ends at a long gap in the samples (window.gap_cut_at gives the time)",
    ANGLE_UNWRAPPED: "jumps of 2π in the angle (a swing through ±π) were unwrapped (count in window.n_unwrapped)",
    SENSOR_SCALE_FITTED: "the angle sensor's scale was identified from the swing itself (effect gain or view): the "
                         "sensor is off its calibration and ω_n, J rest on that fit (the report gives ω_n at the "
                         "nominal scale); calibrate the camera or encoder scale",
    HALVES_DISAGREE: "the final model fitted to each half of the record gives ω_n values that differ beyond their σ: "
                     "the model lacks something that changes with the amplitude or over time (model_form.segments); "
                     "their scatter is in omega_n_u and J_u",
    MODEL_AMBIGUOUS: "another model explains the record about as well (within the BIC margin) and gives another ω_n: "
                     "the data do not decide between them (model_form.competitors names them); the spread is in "
                     "omega_n_u and J_u",
    RELEASES_DISAGREE: "releases of one object identified jointly scatter about the joint ω_n beyond their "
                       "uncertainties (consistency.p < 0.01; consistency.largest_release departs most): the joint σ "
                       "is scaled by the Birge ratio; or two releases' own readings are more than 2 u apart "
                       "(consistency.own_pairwise_releases)",
    ENCODER_ERRORS: "the encoder had time-outs, CRC errors or late replies (counts in acquisition)",
    CAMERA_POSE: "the camera's yaw was beyond the limit (yaw_limit_deg): the angles were corrected; check the mounting",
    MARKER_LOST: "the tracker lost the marker in some frames",
    DROPPED_FRAMES: "the camera dropped frames (gaps in the frame timestamps)",
    CORRUPT_FRAME: "some frames were unreadable or corrupt",
    CAMERA_PERSPECTIVE: "two markers on the pendulum changed their distance with the angle beyond what the camera's "
                        "oblique view (measured and removed) explains: perspective (parts of the swing nearer the "
                        "camera) or a position-dependent tracker bias; the angle keeps an error of that kind "
                        "(acquisition.view.distance_pattern)",
    CAPTURE_SLOWED: "clients (OPC UA, the web page) were served or connected while the sensor was read, and the "
                    "capture's "
                    "sample rate fell below 80 % of the median of the last captures without them "
                    "(acquisition.*.rate_hz): J rests on fewer samples than usual",
    NEGATIVE_INERTIA: "J_object (J − tare) or J_object_axis came out negative, which no part can have: the rig file's tare "
                      "inertia or [object] mass/axis_offset does not fit this set-up",
    CALIBRATION_DUE: "the rig's calibration is past its validity period ([calibration] date + valid_days of the rig file)",
    TENSOR_INCONSISTENT: "a tensor set: the orientations disagree beyond their uncertainties (χ² beyond its 99 % point); "
                         "the orientation with the largest normalised residual is named: a mis-mounted or mis-typed axis",
    TENSOR_UNPHYSICAL: "a tensor set: a principal moment is ≤ 0 or I1 + I2 < I3 beyond the uncertainty, which no "
                       "body can have: check the axes, offsets, mass and tare",
    ORIENTATION_EXCLUDED: "a tensor set: an orientation whose releases were all INVALID was left out (named in the "
                          "reasons); the tensor rests on the others",
}


#: what a flag's condition does to the answer (module doc)
WARNING, INFORMATION = "warning", "information"

#: flag → its grade: WARNING where the condition may move ω_n or J beyond the stated u
GRADES: dict[str, str] = {
    UNMODELED_RESIDUAL: INFORMATION,  # what it does to ω_n is the halves' and the rivals' term of u
    OUTLIERS_REMOVED: INFORMATION,
    PARAMETER_AT_BOUND: INFORMATION,
    FIT_NOT_CONVERGED: WARNING,
    CORRELATED_RESIDUAL: INFORMATION,  # σ and BIC use the fitted noise model
    OUTLIERS_DOWNWEIGHTED: INFORMATION,
    WINDOW_CUT_AT_GAP: INFORMATION,
    ANGLE_UNWRAPPED: INFORMATION,
    SENSOR_SCALE_FITTED: WARNING,  # ω_n at the nominal scale differs, and that difference is not in u
    HALVES_DISAGREE: INFORMATION,  # their scatter is in u
    MODEL_AMBIGUOUS: INFORMATION,  # the rivals lie within the expanded u
    RELEASES_DISAGREE: WARNING,  # one release's u does not reach the others
    ENCODER_ERRORS: INFORMATION,
    CAMERA_POSE: INFORMATION,  # the angles were corrected
    MARKER_LOST: INFORMATION,
    DROPPED_FRAMES: INFORMATION,
    CORRUPT_FRAME: INFORMATION,
    CAMERA_PERSPECTIVE: WARNING,  # the angle keeps a scale error that changes with the angle, not in u
    CAPTURE_SLOWED: INFORMATION,
    NEGATIVE_INERTIA: WARNING,
    CALIBRATION_DUE: WARNING,
    TENSOR_INCONSISTENT: WARNING,
    TENSOR_UNPHYSICAL: WARNING,
    ORIENTATION_EXCLUDED: INFORMATION,  # the tensor rests on the others, with their uncertainty
}

#: the flags graded WARNING, in the table's order
WARNINGS: tuple[str, ...] = tuple(f for f in FLAGS if GRADES[f] == WARNING)


#: flag → its bit in the published bit field: the payload's ``flag_bits``, the Modbus registers ``flags`` (bits
#: 0–15) and ``flags_high`` (16–31), the order MQTT's discovery lists them in (the Modbus map's version, in
#: CHANGELOG.md, says when each bit was given). A flag not in this table sets FLAG_OTHER_BIT, so a new flag is
#: never silently lost.
FLAG_BITS: dict[str, int] = {
    UNMODELED_RESIDUAL: 0,
    OUTLIERS_REMOVED: 1,
    PARAMETER_AT_BOUND: 2,
    FIT_NOT_CONVERGED: 3,
    CORRELATED_RESIDUAL: 4,
    ENCODER_ERRORS: 5,
    CAMERA_POSE: 6,
    MARKER_LOST: 7,
    DROPPED_FRAMES: 8,
    CORRUPT_FRAME: 9,   # map version 2; in version 1 it set bit 15 (other)
    OUTLIERS_DOWNWEIGHTED: 10,  # map version 3
    WINDOW_CUT_AT_GAP: 11,
    ANGLE_UNWRAPPED: 12,
    CALIBRATION_DUE: 13,  # map version 4: the rig's calibration is past its validity period
    NEGATIVE_INERTIA: 14,  # map version 4
    SENSOR_SCALE_FITTED: 16,  # map version 5: register flags_high, bit 0
    CAMERA_PERSPECTIVE: 17,  # map version 6: register flags_high, bit 1
    TENSOR_INCONSISTENT: 18,  # map version 7: a tensor set's flags (register flags_high / tensor_flags)
    TENSOR_UNPHYSICAL: 19,
    ORIENTATION_EXCLUDED: 20,
    HALVES_DISAGREE: 21,  # map version 8: the model's form (register flags_high, bits 5-7)
    MODEL_AMBIGUOUS: 22,
    RELEASES_DISAGREE: 23,
    CAPTURE_SLOWED: 24,  # map version 12: register flags_high, bit 8
}
FLAG_OTHER_BIT = 15


def flag_bits(flags: Iterable[str]) -> int:
    """Bit field of quality flags; unknown flags set bit FLAG_OTHER_BIT."""
    bits = 0
    for f in flags:
        bits |= 1 << FLAG_BITS.get(f, FLAG_OTHER_BIT)
    return bits


def flags_from_bits(bits: int) -> list[str]:
    """Flag names of a bit field (``flags`` | ``flags_high`` << 16); "other" for bit FLAG_OTHER_BIT."""
    names = [name for name, b in FLAG_BITS.items() if bits & (1 << b)]
    if bits & (1 << FLAG_OTHER_BIT):
        names.append("other")
    return names

def describe(flag: str) -> str:
    """The meaning of ``flag`` ("" for a flag outside the table)."""
    return FLAGS.get(flag, "")


def grade(flag: str) -> str:
    """``flag``'s grade (WARNING or INFORMATION; a flag outside the table is a WARNING: nothing says it is not)."""
    return GRADES.get(flag, WARNING)


def warnings(flags: tuple[str, ...] | list[str]) -> tuple[str, ...]:
    """The warnings among ``flags``, in their order."""
    return tuple(f for f in flags if grade(f) == WARNING)


def report_line(flags: tuple[str, ...] | list[str]) -> str:
    """The report's flag line: the warnings first, then what is information."""
    if not flags:
        return "[[Flags]] none"
    warned = warnings(flags)
    told = [f for f in flags if f not in warned]
    return (f"[[Flags]] warnings: {', '.join(warned) or 'none'}"
            + (f"; information: {', '.join(told)}" if told else ""))
