"""What the page says about states and quality flags, in words a technician reads."""

from __future__ import annotations

#: quality flag → what it means for the result (a flag missing here is shown by its name)
FLAG_WORDS: dict[str, str] = {
    "unmodeled_residual": "the residual holds structure no effect in the library explains: J may be biased",
    "outliers_removed": "isolated glitches were removed from the trace before fitting",
    "parameter_at_bound": "a fitted parameter sits at its bound: that effect is poorly determined",
    "fit_not_converged": "the fit did not converge: do not use this J",
    "correlated_residual": "the residual is correlated: uncertainties are Newey–West corrected",
    "encoder_errors": "the encoder link had errors (CRC, time-outs, late replies) during the capture",
    "camera_pose": "the camera is yawed beyond the limit (yaw_limit_deg); the angles were corrected, check the mounting",
    "marker_lost": "the camera lost the marker in some frames",
    "dropped_frames": "camera frames were dropped (gaps in the trace)",
    "corrupt_frame": "corrupt camera frames were skipped",
}

#: sequencer state → what is happening
STATE_WORDS: dict[str, str] = {
    "STARTING": "the appliance is starting",
    "IDLE": "ready: press Measure (or the push button)",
    "ARMED": "recording the pendulum at rest before the release",
    "RELEASING": "solenoid pulse: releasing the pendulum",
    "CAPTURING": "the pendulum swings freely; recording",
    "IDENTIFYING": "identifying the equation of motion",
    "PUBLISHING": "storing and publishing the result",
    "FAULT": "fault: acknowledge it once the cause is fixed",
    "ABORTED": "the measurement was abandoned",
    "STOPPING": "the appliance is stopping",
}


def flag_words(flags) -> list[tuple[str, str]]:
    return [(f, FLAG_WORDS.get(f, "")) for f in flags or ()]
