"""Fixtures the web pages' tests share."""

import pytest


@pytest.fixture
def berlin(monkeypatch):
    """The appliance's clock in Berlin (an hour or two from UTC), set back afterwards."""
    import time

    monkeypatch.setenv("TZ", "Europe/Berlin")
    time.tzset()
    yield
    monkeypatch.undo()
    time.tzset()
