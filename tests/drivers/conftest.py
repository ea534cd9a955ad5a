"""Fixtures of the driver tests: fresh gpiozero mock pins per test."""

import logging

import pytest
from gpiozero.pins.mock import MockFactory


@pytest.fixture
def factory():
    """A fresh MockFactory: pins whose ``states`` record every change with its duration."""
    f = MockFactory()
    yield f
    f.close()


@pytest.fixture(autouse=True)
def _quiet_pymodbus():
    # every injected fault is also an ERROR line from pymodbus; the driver counts them
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)
    return
