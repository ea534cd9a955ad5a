"""Shared test settings. Area fixtures live in each tests/<area>/conftest.py."""

import os
from pathlib import Path

import pytest

# Every test that touches GPIO uses gpiozero's mock pins, never real hardware.
os.environ.setdefault("GPIOZERO_PIN_FACTORY", "mock")
# Plots are written headless.
os.environ.setdefault("MPLBACKEND", "Agg")

#: the areas whose tests run servers, threads and a simulated rig against the clock (Modbus, MQTT, OPC UA,
#: the web page, the sequencer, the encoder bus): marked `clock`. `make test` runs them beside the computations
#: (they wait on their peers while those keep the cores busy), so none may depend on how fast the host is;
#: `pytest -m clock` runs them alone, to try them under a busy loop on each core. A module elsewhere that does
#: the same says `pytestmark = pytest.mark.clock`.
CLOCK_AREAS = frozenset({"service", "firmware_host", "drivers"})
_TESTS = Path(__file__).resolve().parent


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    for item in items:
        if item.path.resolve().relative_to(_TESTS).parts[0] in CLOCK_AREAS:
            item.add_marker(pytest.mark.clock)
