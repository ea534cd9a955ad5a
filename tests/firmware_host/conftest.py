"""Fixtures of the sequencer tests (helpers live in sequencer_harness.py, a unique module name)."""

import logging

import pytest
from gpiozero.pins.mock import MockFactory
from sequencer_harness import Harness


@pytest.fixture
def factory():
    f = MockFactory()
    yield f
    f.close()


@pytest.fixture
def harness(factory):
    made = []

    def make(**kwargs) -> Harness:
        h = Harness(factory, **kwargs)
        made.append(h)
        return h
    yield make
    for h in made:
        h.close()


@pytest.fixture(autouse=True)
def _quiet_pymodbus():
    logging.getLogger("pymodbus").setLevel(logging.CRITICAL)
    return
