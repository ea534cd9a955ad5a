"""Shared test settings. Area fixtures live in each tests/<area>/conftest.py."""

import os

# Every test that touches GPIO uses gpiozero's mock pins, never real hardware.
os.environ.setdefault("GPIOZERO_PIN_FACTORY", "mock")
# Plots are written headless.
os.environ.setdefault("MPLBACKEND", "Agg")
