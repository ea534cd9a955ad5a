"""The timing of one measurement (``SequencerConfig``), checked when it is made."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from .errors import SequencerConfigError

#: longest pre-trigger and capture, s: a record of an hour is far beyond any swing, and a longer one
#: (a typo of 1e12) would only fill the memory sample by sample
MAX_CAPTURE = 3600.0


@dataclass(frozen=True)
class SequencerConfig:
    """Timing of one measurement (angles in rad).

    The physics times (pre_trigger, release_pulse, capture_duration, decay_window,
    min_capture) are s on the sequencer's clock. The two computer time-outs
    (sample_timeout: sensor I/O; identify_timeout: processor time) are real
    seconds: on a ``ScaledClock`` the sequencer divides clock time by its
    ``scale``, so a simulation running 5× faster does not starve the bus or the fit.

    pre_trigger: capture recorded before the release (at rest at the release angle): the last
        pre_trigger seconds before it, however late the release came.
    release_pulse: how long the solenoid is asked to stay on (the solenoid clamps
        it to its own hard maximum).
    capture_duration: the capture ends this long after the release at the latest.
    decay_threshold: the capture ends earlier when the half peak-to-peak angle over
        the last ``decay_window`` falls below this (rad); 0 disables.
    min_capture: the decay test starts only this long after the release.
    sample_timeout: no new sample for this long while capturing → FAULT (capture time-out);
        real s. The release also waits for the first pre-trigger sample (never release blind).
    identify_timeout: identification longer than this → FAULT; real s.
    min_samples: fewer samples in the capture → FAULT instead of a meaningless fit.
    identify_in_worker: run identification in a worker thread (True for the daemon:
        ``poll`` stays responsive); False runs it inside ``poll`` (tests on a ManualClock).
    """

    pre_trigger: float = 0.5
    release_pulse: float = 0.15
    capture_duration: float = 30.0
    decay_threshold: float = 0.0
    decay_window: float = 2.0
    min_capture: float = 5.0
    sample_timeout: float = 1.0
    identify_timeout: float = 60.0
    min_samples: int = 50
    identify_in_worker: bool = True

    def __post_init__(self) -> None:
        def check(name: str, ok: bool, expected: str) -> None:
            if not ok:
                raise SequencerConfigError(f"sequencer: {name} = {getattr(self, name)!r}; expected {expected}")

        def finite(v: Any) -> bool:
            return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)

        check("pre_trigger", finite(self.pre_trigger) and 0 <= self.pre_trigger <= MAX_CAPTURE,
              f"a time >= 0 s and at most {MAX_CAPTURE:g} s")
        check("release_pulse", finite(self.release_pulse) and self.release_pulse > 0, "a time > 0 s")
        check("capture_duration", finite(self.capture_duration) and 0 < self.capture_duration <= MAX_CAPTURE,
              f"a time > 0 s and at most {MAX_CAPTURE:g} s")
        check("decay_threshold", finite(self.decay_threshold) and self.decay_threshold >= 0, "an angle >= 0 rad (0 disables)")
        check("decay_window", finite(self.decay_window) and self.decay_window > 0, "a time > 0 s")
        check("min_capture", finite(self.min_capture) and self.min_capture >= 0, "a time >= 0 s")
        check("sample_timeout", finite(self.sample_timeout) and self.sample_timeout > 0, "a time > 0 s")
        check("identify_timeout", finite(self.identify_timeout) and self.identify_timeout > 0, "a time > 0 s")
        check("min_samples", isinstance(self.min_samples, int) and self.min_samples >= 2, "an integer >= 2")
