"""The bicycle-parameter sets: one object released several times, read by a rate gyro, as its rate and its angle.

data/README.md: a calibration rod and a front wheel on a torsion rod, the
wheel again hung from its rim as a compound pendulum; each release comes as
the gyro's rate (rad/s, its zero left in) and as the rate integrated (rad).
Precision is judged against the plainest fit that would do, a damped
sinusoid over the whole record: the spread of ω_n between the releases of
one object moi gives must be no wider (``SPREAD_RATIO``), unless moi names the
restoring law of the object that moves its ω_n. Honesty: releases more than
``OWN_PAIR_Z`` stated u apart are flagged (releases_disagree) with the two
named, and a release's rate and angle records give one ω_n within the u each
states. The front wheel's sets, three short releases each, are fitted whole
here (seconds); the calibration rod's five releases are the bench's
(bench/bench_precision.py), its law's values across them and one release's
rate against its angle are in test_object_laws.py.
"""

from __future__ import annotations

import functools
import itertools
import math
from pathlib import Path

import pytest

from measurement import flags as F
from measurement.identification import identify
from measurement.joint import CONSISTENT_P, OWN_PAIR_Z, JointResult, identify_releases
from measurement.reports import joint_report, result_report
from measurement.result import IdentificationResult
from service.sources.dispatch import load_source
from service.sources.files import read_rig

from .reference import damped_sinusoid, reading_columns

DATA = Path(__file__).resolve().parents[2] / "data"
#: the object's file name stem, and its number of releases
OBJECTS = {"fwheel_torsional": 3, "fwheel_compound": 3}
#: the widest spread of ω_n between releases moi may give, as a multiple of the damped sinusoid's
SPREAD_RATIO = 1.2


def _files(part: str, reading: str) -> list[Path]:
    suffix = "_rate" if reading == "rate" else ""
    return [DATA / f"bicycle_{part}_first_{i}{suffix}.csv" for i in range(1, OBJECTS[part] + 1)]


@functools.cache
def joint(part: str, reading: str) -> JointResult:
    """``moi identify`` of the object's releases together (the first release's rig: they differ in comments only)."""
    return identify_releases([load_source(f) for f in _files(part, reading)],
                             read_rig(DATA / f"bicycle_{part}_first_1_rig.toml"))


def _u(r: IdentificationResult) -> float:
    return r.omega_n_u if r.omega_n_u is not None else r.omega_n_std


def _spread(w: list[float]) -> float:
    return (max(w) - min(w)) / (sum(w) / len(w))


SETS = [(part, reading) for part in OBJECTS for reading in ("angle", "rate")]


@pytest.mark.parametrize(("part", "reading"), SETS)
def test_the_spread_between_releases_is_no_wider_than_a_plain_damped_sinusoids(part, reading):
    j = joint(part, reading)
    moi = _spread([r.omega_n for r in j.releases])
    plain = _spread([damped_sinusoid(*reading_columns(f))[0] for f in _files(part, reading)])
    # only a law of the object (kept in every release, one sign and size) may move ω_n further apart
    law = "one sign and a consistent size: a law of the object"  # LawAcross.describe of a stable law
    assert moi <= SPREAD_RATIO * plain or any(law in line for r in j.releases for line in r.structure), (moi, plain)


@functools.cache
def alone(part: str, reading: str) -> tuple[IdentificationResult, ...]:
    """``moi identify FILE`` of each release alone (what a one-release recipe gets)."""
    rig = read_rig(DATA / f"bicycle_{part}_first_1_rig.toml")
    return tuple(identify(load_source(f), rig) for f in _files(part, reading))


@pytest.mark.parametrize(("part", "reading"), SETS)
def test_one_release_alone_scatters_no_wider_than_a_plain_damped_sinusoid(part, reading):
    # a cubic spring fitted on 1.4-2.3° swings flips its sign between the wheel's releases on the rod: read at
    # its small-swing limit it spread ω_n 1.9-2.0 × the plain fit's; read at the record's own amplitude (a torsion
    # rig's measurand where its calibration states none), as wide as the plain fit's
    results = alone(part, reading)
    moi = _spread([r.omega_n for r in results])
    # the joint identification reads the releases at one amplitude, their own amplitudes' mean
    together = {(r.omega_n_read_at.basis, r.omega_n_read_at.amplitude) for r in joint(part, reading).releases}
    assert len(together) == 1 and next(iter(together))[0] == ("releases" if part == "fwheel_torsional"
                                                             else "small-swing limit")
    plain = _spread([damped_sinusoid(*reading_columns(f))[0] for f in _files(part, reading)])
    assert moi <= SPREAD_RATIO * plain, (moi, plain)
    if part == "fwheel_torsional":
        assert all(r.omega_n_read_at.basis == "record" and r.omega_n_read_at.amplitude > 0 for r in results)
        assert "ω_n read at  = a swing of" in result_report(results[0])
    else:
        assert all(r.omega_n_read_at.basis == "small-swing limit" for r in results)


@pytest.mark.parametrize(("part", "reading"), SETS)
def test_releases_apart_beyond_their_stated_u_are_flagged_with_the_two_named(part, reading):
    j = joint(part, reading)
    z, a, b = max((abs(x.omega_n - y.omega_n) / math.hypot(_u(x), _u(y)), x.source, y.source)
                  for x, y in itertools.combinations(j.releases, 2))
    c = j.consistency
    assert c["own_pairwise_max"] == pytest.approx(z)
    assert (F.RELEASES_DISAGREE in j.flags) == (z > OWN_PAIR_Z or c["p"] < CONSISTENT_P), (z, c["p"], j.flags)
    if z > OWN_PAIR_Z:
        report = joint_report(j)
        assert f"{a} and {b} are {z:.1f} u apart" in report or f"{b} and {a} are {z:.1f} u apart" in report
    # the wheel hung from its rim: its releases are 0.35 % apart, and its rates say so; its integrated angles
    # hold less well across their records (the 2nd's first half moves by 0.006 rad/s without its first
    # half-swing), and within the u that states they do not disagree. The wheel on the rod: its releases are
    # 0.25 % apart (a plain fit's spread as well) where each record states ± 0.06-0.12 %. Its cubic springs,
    # read at the record's own amplitude, give the plain frequency, and no law extrapolated to zero amplitude
    # widens u to cover the scatter between releases that one record cannot see (remounting): it is flagged
    assert (F.RELEASES_DISAGREE in j.flags) == (part == "fwheel_torsional" or (part, reading) == ("fwheel_compound", "rate"))


#: the releases whose rate and angle records are more than OWN_PAIR_Z stated u apart, and why (none now: the
#: compound wheel's 2nd was, 4.41840 ± 0.00028 rad/s as a rate against 4.42040 ± 0.00071 as an angle, while the
#: release's transient in the rate's first 0.15 s pulled its first half onto its second; the halves are now also
#: asked without the first half-swing: ± 0.0026 and ± 0.011)
APART: dict[tuple[str, int], str] = {}


@pytest.mark.parametrize(("part", "release"), [(part, i) for part, n in OBJECTS.items() for i in range(1, n + 1)])
def test_a_rate_record_and_its_integrated_angle_give_one_omega_n_within_their_u(part, release):
    rate, angle = (joint(part, reading).releases[release - 1] for reading in ("rate", "angle"))
    assert rate.measures == "rate" and rate.offset.unit == "rad/s" and angle.measures == "angle"
    # the gyro's bias, about 1 °/s, is the rate's fitted zero
    assert rate.offset.value is not None and 0.002 < abs(rate.offset.value) < 0.05
    z = abs(rate.omega_n - angle.omega_n) / math.hypot(_u(rate), _u(angle))
    # a known exception stays one until its u covers it; then it joins the others (remove it from APART)
    assert (z > OWN_PAIR_Z) == ((part, release) in APART), (z, rate.omega_n, _u(rate), angle.omega_n, _u(angle))
