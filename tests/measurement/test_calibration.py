"""Table 2 (calibration) and Table 3 (repeatability) of the monocular-vision torsion pendulum paper:
"Research on the Measurement Technology of Rotational Inertia of Rigid Body Based on the Principles of Monocular Vision and Torsion Pendulum"."""

import math

import pytest

from measurement.calibration import Cylinder, Reference, calibrate_torsion
from measurement.errors import CalibrationError
from measurement.stats import repeatability

# Table 2: main frequency ω_m (rad/s), amplitude modulation ζ (1/s), distance L (m)
TABLE2 = [(9.0017, -0.05197, None), (6.9930, -0.06017, 0.05), (5.8686, -0.06579, 0.075), (4.9352, -0.07123, 0.10)]
# §4.2 specimens: mass (kg), diameter (m), own inertia (kg·m²)
SPECIMENS = [(0.5021, 0.06007, 2.265e-4), (0.5006, 0.06004, 2.256e-4)]


def references():
    refs = []
    for omega, zeta, L in TABLE2:
        added = 0.0 if L is None else sum(Cylinder(m, d, L, own).inertia for m, d, own in SPECIMENS)
        refs.append(Reference.from_damped("empty" if L is None else f"L={L}", added, omega, zeta))
    return refs


def test_paper_table2_calibration_within_0_1_percent():
    cal = calibrate_torsion(references())
    assert cal.stiffness == pytest.approx(0.3651, rel=1e-3)
    assert cal.tare_inertia == pytest.approx(4.5043e-3, rel=1e-3)
    assert cal.stiffness_std is not None and 0 < cal.stiffness_std < 1e-3
    # Table 2's "relative true value" is the TOTAL inertia (empty table plus load, as its specimen data show): I0 + load
    assert references()[1].added_inertia + 4.5043e-3 == pytest.approx(7.4631e-3, rel=1e-4)


def test_cylinder_inertia_defaults_to_solid_cylinder():
    m, d, own = SPECIMENS[0]
    assert Cylinder(m, d, 0.0).inertia == pytest.approx(own, rel=1e-3)
    assert Cylinder(m, d, 0.05).inertia == pytest.approx(m * d**2 / 8 + m * 0.05**2)


def test_calibration_needs_distinct_loads():
    with pytest.raises(CalibrationError, match="at least 2"):
        calibrate_torsion(references()[:1])
    with pytest.raises(CalibrationError, match="same added inertia"):
        calibrate_torsion([Reference("a", 0.0, 9.0), Reference("b", 0.0, 8.0)])


def test_paper_table3_standard_deviations_as_printed():
    sphere = [14.6872, 14.6729, 14.6681, 14.6894, 14.6599, 14.6672, 14.7093, 14.6962, 14.6877, 14.6773]
    sleeve = [46.0383, 45.9521, 46.0302, 45.8871, 45.9772, 45.9634, 45.8694, 46.0435, 45.8739, 46.0084]
    uav = [22.3655, 22.3394, 22.3472, 22.3802, 22.3401, 22.3779, 22.3205, 22.2957, 22.3119, 22.3820]
    assert round(repeatability(sphere).std, 4) == 0.0151
    assert round(repeatability(sleeve).std, 4) == 0.0679
    assert round(repeatability(uav).std, 4) == 0.0303


def test_a_reference_released_twice_is_one_point_its_certificates_error_common_to_its_releases():
    k, i0 = 0.3651, 4.5043e-3
    loads = ((0.0, 0.0), (0.005, 2e-5), (0.0125, 6e-5))  # certificates dominate: ω_n's σ is tiny
    once = [Reference(f"r{j}", I, math.sqrt(k / (i0 + I)), 1e-6, u) for j, (I, u) in enumerate(loads)]
    twice = [r for r in once for _ in range(2)]
    a, b = calibrate_torsion(once), calibrate_torsion(twice)
    assert b.stiffness == pytest.approx(a.stiffness, rel=1e-9)
    # six independent points would shrink k's σ by √2; one certificate per reference keeps it
    assert b.stiffness_std == pytest.approx(a.stiffness_std, rel=1e-3)
    assert len(b.residuals) == 6 and len(b.references) == 6
