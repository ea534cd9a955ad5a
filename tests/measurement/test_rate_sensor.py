"""A rate sensor (a gyro) is fitted as a rate: the model's velocity against its reading, its zero a parameter.

Integrating a gyro first turns its zero into a ramp and its noise into a
random walk, which a fit of the angle reads as physics; fitting the rate
itself leaves the zero a constant the fit takes.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from measurement.effects import candidate_effects, resolve_effects
from measurement.errors import RigError, TraceError
from measurement.fit import fit_model
from measurement.model import Model
from measurement.rig import Rig
from measurement.simulate import Pendulum
from measurement.trace import Trace, parse_trace_csv

TORSION = Rig(kind="torsion", stiffness=11.67)


def test_a_trace_with_a_rate_column_and_no_angle_is_a_rate_record():
    rate = parse_trace_csv(["# a gyro", "t,rate", "0,0.5", "0.01,0.4"], source="gyro.csv")
    assert rate.quantity == "rate" and list(rate.angle) == [0.5, 0.4]
    # the angle column is the contract: with both, the trace is an angle trace
    both = parse_trace_csv(["t,angle,rate", "0,0.1,0.5", "0.01,0.11,0.4"])
    assert both.quantity == "angle" and list(both.angle) == [0.1, 0.11]
    again = parse_trace_csv(rate.to_csv().splitlines())
    assert again.quantity == "rate" and np.array_equal(again.angle, rate.angle)
    with pytest.raises(TraceError, match="t and rate"):
        parse_trace_csv(["t,omega", "0,1", "1,2"])
    with pytest.raises(TraceError, match="expected one of angle, rate"):
        Trace(np.array([0.0, 1.0]), np.array([0.0, 1.0]), quantity="speed")


def test_a_gyro_has_no_camera_view():
    gyro = replace(Rig(kind="compound", mass=1.5, com_distance=0.29), measures="rate")
    offered = {e.name for e in candidate_effects(gyro, ["viscous"])}
    assert "drift" in offered and "gain" in offered and "view" not in offered
    with pytest.raises(RigError, match="reads rate"):
        resolve_effects(["viscous", "view"], gyro)


def test_the_velocity_is_fitted_to_a_gyro_reading_with_its_zero_and_drift():
    truth = Pendulum(TORSION, 0.27, {"viscous": {"c": 0.01}})
    t = np.arange(0.0, 20.0, 0.004)
    _, omega = truth.motion(t, 0.15)
    rng = np.random.default_rng(3)
    zero, slope, noise = 0.017, 2e-4, 0.003  # rad/s, rad/s², rad/s: a bias of 1 °/s drifting slowly
    reading = omega + zero + slope * t + noise * rng.standard_normal(t.size)
    fit = fit_model(Model.from_names(replace(TORSION, measures="rate"), ["viscous", "drift"]), t, reading, noise)
    assert abs(fit.value("omega_n") - truth.omega_n) < 4 * fit.stdev("omega_n")
    assert fit.stdev("omega_n") < 1e-4 * truth.omega_n
    assert abs(fit.value("offset") - zero) < 4 * fit.stdev("offset")
    assert abs(fit.value("drift.rate") - slope) < 4 * fit.stdev("drift.rate")
    assert fit.residual_rms < 1.1 * noise
