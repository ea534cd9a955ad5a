"""One measurand for a torsion rig's calibration and its part (measurement.identification.measurand).

A spring that stiffens with the swing: the calibration's references are swung
wide, the part narrow. k is the stiffness at the amplitude the references
were read at, and J = k/ω² takes the part's ω at that amplitude, not the
fitted law's small-swing limit nor the part's own swing.
"""

from __future__ import annotations

import datetime as dt
import math

import pytest

from measurement import Options, Pendulum, Rig, identify, simulate_trace
from measurement.calibration import Reference, calibrate_torsion
from measurement.errors import RigError
from measurement.rig import CalibrationRecord

K, K3, TARE = 0.3651, 0.5 * 0.3651, 4.5e-3  # N·m/rad, N·m/rad³ (hardening: +3.4 % of k at 0.3 rad), kg·m²
ADDED = (0.0, 0.005, 0.0125)
PART = TARE + 0.008
BARE = Rig(kind="torsion", declared=("viscous",))


def swing(inertia: float, theta0: float, seed: int):
    truth = Pendulum(Rig(kind="torsion", stiffness=K, declared=("viscous",)), inertia, {"viscous": {"c": 0.05 * inertia}, "cubic_stiffness": {"k3": K3}})
    return simulate_trace(truth, theta0=theta0, duration=30, rate=100, noise_std=1e-4, seed=seed)


@pytest.fixture(scope="module")
def calibrated() -> tuple[Rig, float]:
    traces = [swing(TARE + a, 0.3, seed) for seed, a in enumerate(ADDED)]
    first = [identify(tr, BARE) for tr in traces]
    amplitude = sum(r.omega_n_read_at.amplitude for r in first) / len(first)
    read = [identify(tr, BARE, Options(reference_amplitude=amplitude)) for tr in traces]
    cal = calibrate_torsion([Reference(f"ref {a}", a, r.omega_n, r.omega_n_u, 1e-7) for a, r in zip(ADDED, read)])
    rig = Rig(kind="torsion", declared=("viscous",), stiffness=cal.stiffness, stiffness_std=cal.stiffness_std,
              tare_inertia=cal.tare_inertia, tare_inertia_std=cal.tare_inertia_std,
              stiffness_tare_covariance=cal.covariance,
              calibration=CalibrationRecord(dt.date(2026, 1, 5), amplitude=amplitude))
    return rig, amplitude


def test_a_part_swung_narrower_than_the_calibration_reads_its_omega_at_the_calibrations_amplitude(calibrated):
    rig, amplitude = calibrated
    # the stiffness at the references' swing, not the spring's small-swing k
    assert rig.stiffness is not None and rig.stiffness > K * (1 + 0.01)
    r = identify(swing(PART, 0.1, 7), rig)
    assert "cubic_stiffness" in r.effects
    assert r.omega_n_read_at.basis == "calibration" and r.omega_n_read_at.amplitude == amplitude
    assert r.J is not None and r.J_u is not None
    assert abs(r.J - PART) <= 2 * r.J_u and abs(r.J / PART - 1) < 2e-3, (r.J, r.J_u, PART)
    # the fitted law's small-swing limit with the same k is off by the spring's stiffening at the calibration's swing
    limit = r.omega_n_read_at.limit
    assert limit is not None and abs(rig.stiffness / limit**2 - PART) > 5 * r.J_u  # 1.8 % against u 0.2 %
    assert any("the amplitude the rig's calibration read its references at" in s for s in r.structure)


def test_without_the_calibrations_amplitude_the_part_is_read_at_its_own_swing(calibrated):
    rig, amplitude = calibrated
    own = identify(swing(PART, 0.1, 7), Rig(**{**rig.__dict__, "calibration": None}))
    assert own.omega_n_read_at.basis == "record" and own.omega_n_read_at.amplitude < 0.5 * amplitude
    # the measure a plain fit makes: J from it is off by the stiffening between the two swings
    assert own.J is not None and own.J / PART - 1 > 0.01
    assert math.isfinite(own.omega_n_u or math.nan)


def test_the_calibrations_amplitude_is_an_optional_key_of_the_rig_file():
    doc = {"rig": {"kind": "torsion", "stiffness": K}, "calibration": {"date": "2026-01-05", "amplitude": 0.2}}
    rig = Rig.from_dict(doc)
    assert rig.calibration is not None and rig.calibration.amplitude == 0.2
    assert Rig.from_dict(rig.to_dict()).calibration == rig.calibration
    unstated = Rig.from_dict({**doc, "calibration": {"date": "2026-01-05"}}).calibration
    assert unstated is not None and unstated.amplitude is None
    with pytest.raises(RigError, match="amplitude must be >= 0 rad"):
        Rig.from_dict({**doc, "calibration": {"date": "2026-01-05", "amplitude": -0.1}})
