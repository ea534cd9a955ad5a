"""The candidates of a discovery round fitted side by side give the result of fitting them one after the other."""

import threading

import numpy as np

from measurement import Pendulum, Rig, identify, simulate_trace
from measurement.identification import discovery, pipeline
from measurement.identification import threads as pool


def test_parallel_candidate_fits_change_nothing(monkeypatch):
    rig = Rig(kind="torsion", stiffness=0.3651, declared=("viscous",))
    # air drag, then a drifting zero: the second round fits two candidates
    truth = Pendulum(rig, 0.0125, {"viscous": {"c": 1e-4}, "quadratic": {"K": 2e-3}, "drift": {"rate": 3e-4}})
    trace = simulate_trace(truth, theta0=0.25, duration=30, rate=200, noise_std=1e-4, quantisation_bits=17, seed=11)
    fitted_on: list[str] = []
    fit_model = pipeline.fit_model

    def recording_fit(*args, **kwargs):
        fitted_on.append(threading.current_thread().name)
        return fit_model(*args, **kwargs)

    monkeypatch.setattr(pipeline, "fit_model", recording_fit)  # the declared model's fits
    monkeypatch.setattr(discovery, "fit_model", recording_fit)  # the candidates'
    results = {}
    for cores in (1, 4):
        monkeypatch.setattr(pool, "usable_cores", lambda cores=cores: cores)
        fitted_on.clear()
        results[cores] = identify(trace, rig)
        threads = {name.startswith("moi-fit") for name in fitted_on}
        assert threads == ({False} if cores == 1 else {False, True})
    one, many = results[1], results[4]
    assert one.added_effects == many.added_effects == ("quadratic", "drift")
    assert [s.candidates for s in one.steps] == [s.candidates for s in many.steps]
    assert any(sum("screened" not in v for v in s.candidates.values()) >= 2 for s in many.steps)
    assert one.J == many.J and one.J_std == many.J_std
    assert np.array_equal(one.arrays["fitted"], many.arrays["fitted"])
