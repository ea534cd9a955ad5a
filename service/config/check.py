"""`moi run --check`: what the configuration file cannot say by itself, checked before the daemon
starts: GPIO pins that exist and are used once, the GPIO backend, the angle sensor's own checks, each
publisher's (ports that can be bound, files that can be read, exposure), the descriptors the clients may hold,
a state directory that can be written. Every problem is one sentence."""

from __future__ import annotations

import importlib
import os
from pathlib import Path

from service.settings import sensor_registry as sensors
from service.settings.checks import Check
from service.settings.config import Config

from .appliance import publisher_tables

#: gpiozero pin factory name → the module it needs
_BACKEND_MODULES = {"lgpio": "lgpio", "rpigpio": "RPi.GPIO", "pigpio": "pigpio", "native": None, "mock": None}


def pin_problems(config: Config) -> list[str]:
    """The GPIO pins of [hardware]: each must be a GPIO of a Raspberry Pi header and be used once
    (gpiozero would otherwise fail at start with a traceback)."""
    hw = config.hardware
    if hw is None:
        return []
    from gpiozero.pins.mock import MockFactory  # only the board's pin table: no hardware is touched

    board = MockFactory().board_info
    problems: list[str] = []
    seen: dict[str, str] = {}
    for device in ("solenoid", "button", "indicator"):
        table = getattr(hw, device)
        if not table or "pin" not in table:
            continue
        spec = table["pin"]
        found = [info for _, info in board.find_pin(spec)]
        if not found or not str(found[0].name).startswith("GPIO"):
            problems.append(f"[hardware.{device}] pin {spec!r} is not a GPIO pin of the Raspberry Pi header "
                            "(expected a BCM number 0–27 or a name like 'GPIO17' or 'BOARD11')")
            continue
        name = str(found[0].name)
        if name in seen:
            problems.append(f"[hardware.{device}] pin {spec!r} is {name}, already the {seen[name]}'s pin")
        seen[name] = device
    return problems


#: descriptors kept for the measurement (sensor, camera, GPIO), the store, logs and the daemon's own threads
DESCRIPTOR_RESERVE = 128


def descriptor_budget(config: Config, limit: int | None = None) -> Check:
    """Whether the clients' connection caps of every protocol, with ``DESCRIPTOR_RESERVE`` kept for the
    measurement and the store, fit under the process's descriptor limit (systemd's LimitNOFILE, 1,024)."""
    import resource

    limit = limit if limit is not None else resource.getrlimit(resource.RLIMIT_NOFILE)[0]
    caps: dict[str, int] = {}
    for name, table in publisher_tables().items():
        settings = config.publishers.get(name)
        if table.descriptors is not None and settings is not None:
            caps.update(table.descriptors(settings))
    used = sum(caps.values()) + DESCRIPTOR_RESERVE
    detail = (", ".join(f"{k} {v}" for k, v in caps.items()) or "no servers") + \
        f" + {DESCRIPTOR_RESERVE} kept for the measurement and the store = {used} of {limit} descriptors"
    return Check("connection caps", used <= limit, detail + ("" if used <= limit else ": lower max_connections"))


def _gpio_checks(config: Config) -> list[Check]:
    """The pins of the header and the GPIO backend's library, on hardware."""
    hw = config.hardware
    if hw is None or config.simulated:
        return []
    checks = [] if pin_problems(config) else [Check("GPIO pins", True, "each a GPIO of the header, each used once")]
    backend = hw.gpio_backend or os.environ.get("GPIOZERO_PIN_FACTORY")
    module = _BACKEND_MODULES.get(backend or "lgpio", backend)
    if module:
        try:
            importlib.import_module(module)
            checks.append(Check("GPIO backend", True, f"{backend or 'lgpio'} ({module} importable)"))
        except Exception as exc:  # an import of a hardware library may fail in many ways
            checks.append(Check("GPIO backend", False, f"{backend or 'lgpio'}: cannot import {module} "
                                f"({type(exc).__name__}: {exc}); on a Pi: pip install 'moi[pi]'"))
    return checks


def _publisher_checks(config: Config) -> list[Check]:
    """Each publisher's own findings of its settings (its table's ``start_checks``), in the registry's order."""
    checks: list[Check] = []
    for name, table in publisher_tables().items():
        settings = config.publishers.get(name)
        if table.start_checks is not None and settings is not None:
            checks += table.start_checks(settings)
    return checks


def _state_directory(config: Config) -> Check:
    state = Path(config.state_dir)
    parent = state if state.exists() else next((p for p in state.parents if p.exists()), Path("/"))
    writable = os.access(parent, os.W_OK)
    return Check("state directory", writable, f"{state}" + ("" if writable else f": {parent} is not writable"))


def _calibrations(config: Config) -> list[Check]:
    """Each rig the appliance measures with (the set-up's, each recipe's own): one without a calibration record is
    a warning in the words every door says (``service.parts.calibration.uncalibrated``), not a refusal."""
    import time

    from service.parts.calibration import calibration_state, uncalibrated

    rigs = [("rig", config.rig)] + [(f"rig of recipe {r.name}", r.rig) for r in
                                    (config.recipes.recipes if config.recipes is not None else []) if r.rig is not None]
    checks = []
    for what, rig in rigs:
        state = calibration_state(rig, [], time.time())
        words = uncalibrated(state)
        if words is not None:
            checks.append(Check(what, True, words + (": Measure is refused ([device] require_calibration)"
                                                     if config.require_calibration else ""), warning=True))
        elif state is not None and state["due"]:
            checks.append(Check(what, True, f"calibration expired on {state['valid_until']}: its measurements are "
                                "refused until `moi calibrate` renews it", warning=True))
        elif state is not None:
            checks.append(Check(what, True, f"calibrated {state['date']}"
                                + (f", valid until {state['valid_until']}" if state["valid_until"] else "")))
    return checks


def check_config(config: Config) -> list[Check]:
    """Every check of the configuration and of the environment it names: the appliance's own, the angle sensor's
    (its ``health``) and each publisher's (its table's ``start_checks``)."""
    checks = [Check("configuration", True, f"{config.source} parsed")]
    checks += [Check("GPIO pins", False, p) for p in pin_problems(config)]
    checks += _gpio_checks(config)
    if config.hardware is not None and not config.simulated:
        checks += [Check(*line) for line in sensors.sensor(config.hardware.sensor).health(config)]
    return [*checks, *_calibrations(config), *_publisher_checks(config), descriptor_budget(config),
            _state_directory(config)]
