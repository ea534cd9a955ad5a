"""Recordings as people export them, read as they come and held to their authors' own numbers.

data/userdata/ holds a phyphox export of a phone's gyro on a racquet hung as a pendulum (five releases
between pauses and handling) and two Tracker exports of a string pendulum (provenance in data/README.md).
A measured period is compared like with like: the authors counted theirs on the swing as it was, at its
amplitude, where 2π/ω_n is the small-swing limit.
"""

from __future__ import annotations

import functools
import math
from pathlib import Path

import numpy as np
import pytest

from measurement import Options, identify
from measurement.joint import identify_releases
from measurement.periods import amplitude_factor
from service.sources.dispatch import load_releases
from service.sources.files import read_rig

ROOT = Path(__file__).resolve().parents[2]
PHYPHOX = ROOT / "data" / "userdata" / "phyphox_racquet_x_14-02-08"
TRACKER = ROOT / "data" / "userdata" / "tracker_string_pendulum"
#: the authors' period (s) and its 1σ: the racquet's zero crossings over 22 trials; the string pendulum's table
RACQUET_PERIOD = (1.436, 0.039)
RACQUET_J = (0.0968, 0.0054)
STRING_PERIOD = {"8048": (2.284, 0.0008), "8049": (2.148, 0.0008)}


@functools.cache
def racquet():
    return load_releases(PHYPHOX)


@functools.cache
def identified(path: Path, rig: str):
    (trace,) = load_releases(path)
    return identify(trace, read_rig(ROOT / "examples" / rig), Options())


def test_the_phyphox_log_is_split_into_its_five_releases_and_the_handling_left_out():
    traces = racquet()
    starts = [tr.meta["release"]["free_swing_from"] for tr in traces]
    # by eye on the gyro's x rate: a hand release in each START..PAUSE section, the third after 48 s of handling
    assert starts == pytest.approx([4.77, 26.13, 91.50, 111.60, 130.80], abs=0.3)
    assert "handling" in traces[0].meta["log"]["sections_without_a_release"]
    for tr in traces:
        assert tr.quantity == "rate" and tr.meta["axis"]["swing_about"] == "Gyroscope x (rad/s)"
        assert tr.meta["axis"]["cosine"] > 0.99


@functools.cache
def racquet_joint():
    return identify_releases(racquet(), read_rig(ROOT / "examples" / "racquet_phyphox.toml"))


def test_the_racquet_s_releases_agree_and_give_the_authors_period_and_inertia_within_u():
    joint = racquet_joint()
    assert joint.consistency["p"] >= 0.01, "the five releases of one racquet agree on one ω_n"
    t, u = RACQUET_PERIOD
    for r in joint.releases:
        p = r.periods
        if "halves_disagree" in r.flags:  # a release whose model does not hold says so and carries it in its u
            assert r.omega_n_u > 20 * joint.omega_n_u
            continue
        assert 0.25 < p.amplitude < 0.5  # the authors' swings: 0.3–0.5 rad
        assert abs(p.at_amplitude - t) < math.hypot(p.at_amplitude_u, u)
    assert abs(joint.J - RACQUET_J[0]) < math.hypot(joint.J_u, RACQUET_J[1])
    # the same ω_n as one period: 2π/ω_n at the authors' swings (0.3–0.5 rad) lies within u of theirs
    for amplitude in (0.3, 0.5):
        period = 2 * math.pi / joint.omega_n * amplitude_factor("compound", amplitude)
        assert abs(period - t) < u


@pytest.mark.parametrize("name", sorted(STRING_PERIOD))
def test_a_tracker_export_gives_the_authors_period_among_the_periods_its_swing_went_through(name):
    r = identified(TRACKER / f"{name}.txt", f"string_pendulum_{name}.toml")
    p = r.periods
    t, u = STRING_PERIOD[name]
    # counted over the whole record (the swing decays to about a third) and at its largest swing: a period
    # counted on any stretch of this record lies between them
    assert p.counted - math.hypot(p.counted_u, u) < t < p.at_amplitude + math.hypot(p.at_amplitude_u, u)
    assert p.small_swing < p.counted < p.at_amplitude
    assert r.periods.g == pytest.approx(r.omega_n**2 * read_rig(ROOT / "examples" / f"string_pendulum_{name}.toml").length)


def authors_period_sigma() -> float:
    """The authors' own periods' scatter (s) about the pendulum's law over their eight lengths.

    T² = (4π²/g)·L + c holds for a string pendulum whatever g and the bob's offset c; their periods
    scatter about its best fit by more than their stated ±0.8 ms (a length's ±0.5 mm moves a period by
    under 0.5 ms), so that scatter, with two fitted constants, is what one of their periods is worth.
    """
    length, period = np.loadtxt(TRACKER / "PeriodVsLength.txt", skiprows=1, usecols=(0, 1)).T
    law = np.polyfit(length, period**2, 1)
    residual = period - np.sqrt(np.polyval(law, length))
    return float(np.sqrt(np.sum(residual**2) / (length.size - 2)))


@pytest.mark.parametrize("name", sorted(STRING_PERIOD))
def test_a_tracker_export_gives_the_authors_period_at_its_swing_within_what_their_periods_are_worth(name):
    sigma = authors_period_sigma()
    assert 0.002 < sigma < 0.008, "their eight periods scatter by a few ms about T² ∝ L"
    p = identified(TRACKER / f"{name}.txt", f"string_pendulum_{name}.toml").periods
    t, _ = STRING_PERIOD[name]
    # like with like: a period read off the start of the record, where the swing is widest
    assert abs(p.at_amplitude - t) < math.hypot(p.at_amplitude_u, sigma)
