"""Monocular vision: from camera frames of a target on the swinging body to the swing angle.

    config     the camera file (intrinsics, distortion, marker radius/distance, pose settings, [target])
    target     the [target] table: tag, blob, blobs, patch or edge; view; region of interest
    locators   frame → a vector fixed to the body: printed tag, blob(s), textured patch (ECC)
    body       that vector → angle: pivot from the arc, the oblique view removed when the swing shows it
    quality    tracked share, longest gap, jitter, jumps, a target that does not move: the refusal rules
    locate     grey frame → marker edge, sub-pixel, in ideal normalised coordinates (MarkerTracker)
    geometry   normalised coordinate → angle, exact (R·sin θ lateral, R·(1 − cos θ) deeper)
    pose       the camera's yaw, fitted as a parameter of the projection over a whole swing
    pipeline   frames → Trace (gaps and flags for lost/corrupt/dropped frames, yaw corrected)
    marker_pair  two markers on the pendulum → angle, the camera's oblique view measured from their distance
    render     ray-traced synthetic frames: the truth for tests, bench and the mock camera
    render_plane  frames of a body turning in the image plane (tag, bob, blobs, plate) for the other targets

Pure numpy/scipy/opencv: decoding files and talking to cameras live in
``drivers.video_file`` and ``drivers.camera``.
"""

from typing import TYPE_CHECKING

from .._lazy import lazy_exports

#: public name → its submodule, imported on first use (PEP 562): reading a camera file
#: (``measurement.vision.config``) must not load OpenCV and scipy.
_WHERE = {
    **dict.fromkeys(("CameraConfig", "CameraModel", "MarkerGeometry", "PoseSettings"), "config"),
    **dict.fromkeys(("angle_from_normalised", "normalised_from_angle"), "geometry"),
    **dict.fromkeys(("MarkerObservation", "MarkerTracker", "TrackerSettings"), "locate"),
    **dict.fromkeys(("Tracking", "VisionSettings", "count_dropped", "trace_from_tracking", "track_frames"), "pipeline"),
    **dict.fromkeys(("PoseEstimate", "estimate_yaw"), "pose"),
    **dict.fromkeys(("CameraPose", "Imaging", "MarkerPattern", "MarkerRenderer"), "render"),
    **dict.fromkeys(("MarkerTrack", "PairView", "measure_view", "pair_angle", "pair_trace", "parse_marker_csv"),
                    "marker_pair"),
}


__getattr__, __dir__ = lazy_exports(__name__, globals(), _WHERE)


if TYPE_CHECKING:  # pragma: no cover
    from .config import CameraConfig, CameraModel, MarkerGeometry, PoseSettings
    from .geometry import angle_from_normalised, normalised_from_angle
    from .locate import MarkerObservation, MarkerTracker, TrackerSettings
    from .marker_pair import MarkerTrack, PairView, measure_view, pair_angle, pair_trace, parse_marker_csv
    from .pipeline import Tracking, VisionSettings, count_dropped, trace_from_tracking, track_frames
    from .pose import PoseEstimate, estimate_yaw
    from .render import CameraPose, Imaging, MarkerPattern, MarkerRenderer

__all__ = [
    "CameraConfig", "CameraModel", "MarkerGeometry", "PoseSettings", "angle_from_normalised",
    "normalised_from_angle", "MarkerObservation", "MarkerTracker", "TrackerSettings", "Tracking", "VisionSettings",
    "count_dropped", "trace_from_tracking", "track_frames", "PoseEstimate", "estimate_yaw", "CameraPose", "Imaging",
    "MarkerPattern", "MarkerRenderer", "MarkerTrack", "PairView", "measure_view", "pair_angle", "pair_trace",
    "parse_marker_csv",
]
