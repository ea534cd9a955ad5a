"""The demo rig, part and camera: what the simulated appliance runs with when nothing else is given.

One definition for `moi run` without a ``[hardware]`` table, ``[simulation]``'s
defaults, `moi measure --sim`, `moi demo` and `moi camera-check` on the mock
camera. The rig is the torsion rig of ``examples/torsion_rig.toml``.
"""

from __future__ import annotations

from typing import Any

from measurement.rig import Rig

#: the simulated rig when no rig file is given: torsion, k = 0.3651 N·m/rad, empty fixture 4.5043e-3 kg·m², with
#: the uncertainties `moi calibrate examples/calibration.toml` gives them (k and I0 correlated) and a 20 ppm clock
DEMO_RIG = Rig(kind="torsion", stiffness=0.3651, stiffness_std=3.373e-4, tare_inertia=4.5043e-3, tare_inertia_std=4.177e-6,
               stiffness_tare_covariance=1.4076e-9, clock_accuracy_ppm=20.0, declared=("viscous",))

#: true J of the simulated part, kg·m²
DEMO_INERTIA = 0.0125

#: true damping of the simulated rig: effect → {parameter: value} (viscous c in N·m·s/rad, Coulomb T_c in N·m)
DEMO_EFFECTS: dict[str, dict[str, float]] = {"viscous": {"c": 1.5e-4}, "coulomb": {"Tc": 1.2e-4}}

#: release angle of the simulated pendulum, rad
DEMO_THETA0 = 0.25

#: angle noise of the simulated encoder in `moi measure --sim` and `moi demo`, rad (about one count of a
#: 17-bit encoder; with none, the count steps of a slow swing are a staircase, a structured residual)
SIM_ENCODER_NOISE = 5e-5

#: default time scale of `moi measure --sim` and `moi demo` with the simulated encoder: real time. The
#: client and the simulated device share one interpreter; their round trip jitters by some 20 µs of wall
#: time (more on a busy host), and a faster clock multiplies that in simulated time: at 2× and above the
#: timestamp jitter already colours the residual of a 17-bit encoder (correlated_residual, outliers)
SIM_ENCODER_TIME_SCALE = 1.0

#: largest [simulation] time_scale of the simulated encoder: its Modbus link serves some 500–1500 reads per
#: wall-clock second (bench/bench_encoder.py), about 30 samples per simulated second at 20× (some 35 per swing of
#: the demo rig) on a busy 2-core host; at 50× it was 7
MAX_ENCODER_TIME_SCALE = 20.0


def sim_sample_timeout(time_scale: float) -> float:
    """The capture time-out (real s) of `moi measure --sim` and `moi demo` with the simulated encoder: 3 s, or a
    fifth of the time scale when that is longer. Its server answers from the same interpreter as its client, so a
    busy host silences both ends of the bus at once (a lossy link at 2× went 1 s without a sample beside a busy
    loop per core), which a real encoder on its own bus never is: the hardware's 1 s would fault a rig that
    works. A dead bus is still a FAULT, 3 s after its last sample."""
    return max(3.0, 0.2 * time_scale)


#: the simulated camera when no camera file is given (the camera file's tables): 640×480 px at
#: 100 frames/s, 56° field of view, the marker on a 0.10 m radius seen from 0.25 m (240 px per rad at rest)
DEMO_CAMERA: dict[str, Any] = {
    "camera": {"width": 640, "height": 480, "fps": 100.0, "fx": 600.0, "fy": 600.0, "cx": 319.5, "cy": 239.5,
               "distortion": [0.0, 0.0, 0.0, 0.0, 0.0]},
    "marker": {"radius": 0.10, "distance": 0.25},
}

#: BCM pins of the simulated solenoid and push button (mock pins) when no [hardware] table gives them
SIM_SOLENOID_PIN = 17
SIM_BUTTON_PIN = 27


def demo_camera() -> Any:
    """``DEMO_CAMERA`` as a ``measurement.vision.CameraConfig`` (imported here: the vision package loads OpenCV)."""
    from measurement.vision.config import CameraConfig

    return CameraConfig.from_dict(DEMO_CAMERA)
