"""What a test does when a component of the suite (a Debian program: Mosquitto, Chromium and its driver,
FFmpeg, OpenSSL) is missing: skip with a note on a developer's machine, fail under CI (``CI=true``), where a
green run must have run every test. ``make test`` installs them when it can (scripts/component.sh)."""

from __future__ import annotations

import os
from typing import NoReturn

import pytest


def under_ci() -> bool:
    """True when the suite runs under CI (``CI=true``, as CI services set it)."""
    return os.environ.get("CI") == "true"


def missing(reason: str) -> NoReturn:
    """A component this test needs is missing (``reason`` says which and how to install it): the test fails
    under CI, else it skips."""
    if under_ci():
        pytest.fail(f"{reason}; under CI=true a missing component fails the run", pytrace=False)
    pytest.skip(reason)
