"""A component of the suite missing (Mosquitto, Chromium and chromedriver, FFmpeg): a note and skipped tests on a
developer's machine, a failed step and failed tests under CI (CI=true), so that a green CI has run them all."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

from tests.components import missing

REPO = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("ci", [None, "false", "true"])
def test_a_missing_component_skips_its_test_but_fails_it_under_ci(monkeypatch, ci):
    if ci is None:
        monkeypatch.delenv("CI", raising=False)
    else:
        monkeypatch.setenv("CI", ci)
    outcome = pytest.fail.Exception if ci == "true" else pytest.skip.Exception
    with pytest.raises(outcome, match="mosquitto binary not found"):
        missing("mosquitto binary not found")


def test_the_broker_fixture_fails_under_ci_without_mosquitto(monkeypatch):
    from tests.service import conftest

    monkeypatch.setattr(conftest, "MOSQUITTO", None)
    monkeypatch.setenv("CI", "true")
    with pytest.raises(pytest.fail.Exception, match="under CI=true a missing component fails the run"):
        conftest._need_mosquitto()


@pytest.mark.parametrize("target", ["broker", "browser", "ffmpeg", "systemd"])
def test_the_make_step_of_a_missing_component_fails_under_ci(tmp_path, target):
    make = shutil.which("make")
    assert make is not None, "make is what runs the suite"
    bare = tmp_path / "bin"  # a PATH with none of the components nor apt-get: nothing can be found or installed
    bare.mkdir()
    (bare / "id").symlink_to(shutil.which("id") or "/usr/bin/id")
    env = {"PATH": str(bare), "HOME": str(tmp_path)}

    def step(**extra: str) -> subprocess.CompletedProcess:
        return subprocess.run([make, "-s", "-C", str(REPO), target], env=env | extra, capture_output=True, text=True,
                              timeout=60)

    relaxed = step()
    assert relaxed.returncode == 0 and "note:" in relaxed.stdout and "will be skipped" in relaxed.stdout
    strict = step(CI="true")
    assert strict.returncode != 0 and "under CI=true" in strict.stderr and "must run" in strict.stderr
