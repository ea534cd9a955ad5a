"""`moi run --check`: what the configuration file cannot say by itself, checked before the daemon
starts: GPIO pins that exist and are used once, files that can be read, the GPIO backend, the
serial port or camera, and ports that can be bound. Every problem is one sentence."""

from __future__ import annotations

import importlib
import os
import socket
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from service.devices.sensors import registry as sensors
from service.publish.modbus.settings import network_exposure

from .appliance import Config

#: gpiozero pin factory name → the module it needs
_BACKEND_MODULES = {"lgpio": "lgpio", "rpigpio": "RPi.GPIO", "pigpio": "pigpio", "native": None, "mock": None}


@dataclass(frozen=True)
class Check:
    """One finding. ok: the daemon can start with it. warning: it can, but the user should know (an
    exposure chosen perhaps by accident)."""

    what: str
    ok: bool
    detail: str
    warning: bool = False

    def line(self) -> str:
        mark = "PROBLEM" if not self.ok else "WARNING" if self.warning else "ok     "
        return f"{mark}  {self.what}: {self.detail}"


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


def _readable(path: str | None, what: str) -> Check | None:
    if not path:
        return None
    p = Path(path)
    if not p.is_file():
        return Check(what, False, f"{path} does not exist or is not a file")
    if not os.access(p, os.R_OK):
        return Check(what, False, f"{path} is not readable by this user")
    return Check(what, True, str(path))


def _web_secrets(web: Any) -> list[Check]:
    """The token file and the users file, read as the web page reads them at start (a token file not there yet
    is made at the first start unless it is named)."""
    from service.errors import StartupError
    from service.publish.web.auth import read_token, read_users

    checks = []
    if web.token_file is not None:
        try:
            read_token(web.token_file, create=False)
            mode = Path(web.token_file).stat().st_mode & 0o077
            checks.append(Check("web token_file", True, web.token_file + (
                f": readable by other users (mode {mode:o}); chmod 600 it" if mode else ""), warning=bool(mode)))
        except StartupError as exc:
            checks.append(Check("web token_file", False, str(exc)))
    if web.users_file is not None:
        try:
            checks.append(Check("web users_file", True, f"{web.users_file}: {len(read_users(web.users_file))} user(s)"))
        except StartupError as exc:
            checks.append(Check("web users_file", False, str(exc)))
    return checks


def _opcua_doors(ua: Any) -> list[Check]:
    """The OPC UA server's trusted clients (a directory, as the start needs) and who may come in unencrypted or
    without a user."""
    checks = []
    if ua.trusted_clients is not None:
        ok = Path(ua.trusted_clients).is_dir()
        checks.append(Check("OPC UA trusted_clients", ok, ua.trusted_clients + ("" if ok else " is not a directory")))
    if ua.anonymous or ua.allow_unencrypted:
        doors = [d for d, on in (("clients without a user (anonymous = true)", ua.anonymous),
                                 ("unencrypted sessions (allow_unencrypted = true)", ua.allow_unencrypted)) if on]
        checks.append(Check("OPC UA exposure", True, f"{' and '.join(doors)} on {ua.host}:{ua.port}", warning=True))
    return checks


#: descriptors kept for the measurement (sensor, camera, GPIO), the store, logs and the daemon's own threads
DESCRIPTOR_RESERVE = 128


def descriptor_budget(config: Config, limit: int | None = None) -> Check:
    """Whether the clients' connection caps of every protocol, with ``DESCRIPTOR_RESERVE`` kept for the
    measurement and the store, fit under the process's descriptor limit (systemd's LimitNOFILE, 1,024)."""
    import resource

    limit = limit if limit is not None else resource.getrlimit(resource.RLIMIT_NOFILE)[0]
    caps = {}
    if config.modbus is not None and config.modbus.mode == "tcp":
        caps["Modbus"] = config.modbus.max_connections
    web: Any = getattr(config, "web", None)
    if web is not None:
        # aiohttp accepts up to a backlog's worth beyond the cap before it closes any
        caps["web"] = 2 * web.max_connections + web.max_streams
    if config.opcua is not None:
        caps["OPC UA"] = config.opcua.max_connections
    used = sum(caps.values()) + DESCRIPTOR_RESERVE
    detail = (", ".join(f"{k} {v}" for k, v in caps.items()) or "no servers") + \
        f" + {DESCRIPTOR_RESERVE} kept for the measurement and the store = {used} of {limit} descriptors"
    return Check("connection caps", used <= limit, detail + ("" if used <= limit else ": lower max_connections"))


def _bindable(host: str, port: int, what: str) -> Check:
    if port == 0:
        return Check(what, True, f"{host}: any free port")
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
        with socket.socket(infos[0][0], socket.SOCK_STREAM) as s:
            s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            s.bind(infos[0][4])
    except OSError as exc:
        return Check(what, False, f"cannot listen on {host}:{port}: {exc.strerror or exc} (a running daemon?)")
    return Check(what, True, f"{host}:{port} free")


def check_config(config: Config) -> list[Check]:  # noqa: C901
    """Every check of the configuration and of the environment it names."""
    checks: list[Check] = [Check("configuration", True, f"{config.source} parsed")]
    checks += [Check("GPIO pins", False, p) for p in pin_problems(config)]
    hw = config.hardware
    if hw is not None and not config.simulated:
        if not pin_problems(config):
            checks.append(Check("GPIO pins", True, "each a GPIO of the header, each used once"))
        backend = hw.gpio_backend or os.environ.get("GPIOZERO_PIN_FACTORY")
        module = _BACKEND_MODULES.get(backend or "lgpio", backend)
        if module:
            try:
                importlib.import_module(module)
                checks.append(Check("GPIO backend", True, f"{backend or 'lgpio'} ({module} importable)"))
            except Exception as exc:  # an import of a hardware library may fail in many ways
                checks.append(Check("GPIO backend", False, f"{backend or 'lgpio'}: cannot import {module} "
                                    f"({type(exc).__name__}: {exc}); on a Pi: pip install 'moi[pi]'"))
        checks += [Check(*line) for line in sensors.sensor(hw.sensor).health(config)]
    m = config.mqtt
    if m is not None:
        for path, what in ((m.password_file, "MQTT password_file"), (m.ca_file, "MQTT ca_file"),
                           (m.cert_file, "MQTT cert_file"), (m.key_file, "MQTT key_file")):
            c = _readable(path, what)
            if c is not None:
                checks.append(c)
    mb = config.modbus
    if mb is not None:
        if mb.mode == "tcp":
            checks.append(_bindable(mb.host, mb.port, "Modbus TCP port"))
            exposure = network_exposure(mb)
            if exposure is not None:
                checks.append(Check("Modbus exposure", True, exposure + ("" if mb.allow_from else
                                    "; name the PLCs in [modbus] allow_from"), warning=not mb.allow_from))
        elif mb.serial_port and "://" not in mb.serial_port:
            ok = Path(mb.serial_port).exists()
            checks.append(Check("Modbus RTU port", ok, mb.serial_port + (" present" if ok else " does not exist")))
    web: Any = getattr(config, "web", None)
    if web is not None:
        checks.append(_bindable(web.host, web.port, "web page port"))
        checks += _web_secrets(web)
    ua = config.opcua
    if ua is not None:
        checks.append(_bindable(ua.host, ua.port, "OPC UA port"))
        # a certificate or key not there yet is made at the first start: checked only when it exists
        made = [(p, w) for p, w in ((ua.certificate, "OPC UA certificate"), (ua.private_key, "OPC UA private_key"))
                if p and Path(p).exists()]
        for path, what in [(ua.password_file, "OPC UA password_file"), *made]:
            c = _readable(path, what)
            if c is not None:
                checks.append(c)
        checks += _opcua_doors(ua)
    checks.append(descriptor_budget(config))
    state = Path(config.state_dir)
    parent = state if state.exists() else next((p for p in state.parents if p.exists()), Path("/"))
    writable = os.access(parent, os.W_OK)
    checks.append(Check("state directory", writable, f"{state}" + ("" if writable else f": {parent} is not writable")))
    return checks
