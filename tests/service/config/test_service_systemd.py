"""The systemd unit: the settings the issue requires, and that systemd itself accepts it."""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

from tests.components import missing

UNIT = Path(__file__).resolve().parents[3] / "systemd" / "moi.service"


def unit() -> dict[str, list[str]]:
    values: dict[str, list[str]] = {}
    for line in UNIT.read_text().splitlines():
        line = line.strip()
        if line and not line.startswith(("#", "[")) and "=" in line:
            k, v = line.split("=", 1)
            values.setdefault(k, []).append(v)
    return values


def test_the_unit_is_a_notify_service_with_a_watchdog_and_restart():
    u = unit()
    assert u["Type"] == ["notify"]
    assert u["WatchdogSec"] and u["Restart"] == ["on-failure"]
    assert "moi run --config" in u["ExecStart"][0]
    assert u["StateDirectory"] == ["moi"]
    assert u.get("DynamicUser") == ["yes"] or u.get("User")
    assert set(u["SupplementaryGroups"][0].split()) >= {"gpio", "dialout", "video"}
    # hardening must not hide the devices the appliance drives
    assert u.get("PrivateDevices", ["no"]) == ["no"]
    allowed = " ".join(u["DeviceAllow"])
    for dev in ("gpiochip", "ttyUSB", "ttyAMA", "video4linux"):
        assert dev in allowed
    assert u["NoNewPrivileges"] == ["yes"] and u["ProtectSystem"] == ["strict"]
    # the stop timeout leaves room for the graceful stop (10 s identification + 2 s MQTT flush)
    assert int(u["TimeoutStopSec"][0].rstrip("s")) >= 20
    # a bounded number of descriptors (the Modbus connection cap keeps a client flood far below it)
    assert 256 <= int(u["LimitNOFILE"][0]) <= 4096
    # lgpio writes its notification pipes into the working directory: the (writable) state directory
    assert u["WorkingDirectory"] == ["/var/lib/moi"] and "LG_WD=/var/lib/moi" in u["Environment"]


def test_systemd_analyze_accepts_the_unit():
    if shutil.which("systemd-analyze") is None:
        missing("systemd-analyze not found (Debian package systemd; `make test` installs it)")
    r = subprocess.run(["systemd-analyze", "verify", str(UNIT)], capture_output=True, text=True, timeout=60)
    problems = [line for line in (r.stdout + r.stderr).splitlines()
                if line.strip() and "is not executable" not in line  # /opt/moi is not installed here
                and "No such file or directory" not in line]
    assert not problems, problems
