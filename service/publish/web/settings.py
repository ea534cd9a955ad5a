"""``[web]``: the appliance's own web page (bind address, port, the token file for actions)."""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from measurement.units import ASCII_NAMES, INERTIA_UNITS, inertia_unit
from service.errors import ConfigError, StartupError
from service.publish.replies import CONTACT
from service.settings.checks import Check, bindable
from service.settings.schema import PublisherTable

from .auth import read_token, read_users

#: the name of the plot kept with each measurement in the store
PLOT_NAME = "plot.png"

#: the token file used when ``[web] token_file`` is not given: in the state directory, created on first start
DEFAULT_TOKEN_FILE_NAME = "web-token"


@dataclass(frozen=True)
class WebSettings:
    """The appliance's web page (SI units). Each key's meaning and limits: ``KEYS`` below, from which the
    configuration's ``[web]`` table is built.

    ``max_connections`` and ``request_timeout`` keep the descriptors a client can hold bounded (they stay with
    the measurement, the PLC and MQTT); ``server_names`` refuses a request naming another host in its Host
    header (a DNS-rebinding page on a LAN browser could otherwise read every result)."""

    host: str = "127.0.0.1"
    port: int = 8080
    token_file: str | None = None
    page_size: int = 25
    max_connections: int = 64
    request_timeout: float = 15.0
    server_names: tuple[str, ...] = ()
    display_unit: str = "kg·m²"
    shift_starts: tuple[str, ...] = ("06:00", "14:00", "22:00")
    users_file: str | None = None
    max_streams: int = 16
    max_streams_per_client: int = 4
    stream_lifetime: float = 600.0
    time_format: str = "%Y-%m-%d %H:%M:%S"
    contact: str = CONTACT


#: each key of the configuration's ``[web]`` table: what it means, its unit and its limits (the table is
#: built from this and the dataclass's fields: ``service.config.appliance.SCHEMA``)
KEYS: dict[str, dict] = {
    "host": dict(doc="listen address: 127.0.0.1 this machine only, 0.0.0.0 every interface (the LAN)"),
    "port": dict(doc="TCP port (0: any free port)", min=0, max=65535),
    "token_file": dict(doc="file holding the password/token every action (Measure, Abort) needs (default: "
                       "web-token in the state directory, made with a random token on first start)", kind="path"),
    "page_size": dict(doc="measurements per history page", min=1, max=500),
    "max_connections": dict(doc="browser connections at once; one more is closed at once", min=1, max=512),
    "request_timeout": dict(doc="close a connection that sent no complete request for this long, s", min=0,
                            min_open=True, max=3600),
    "server_names": dict(doc="host names the page is reached by besides IP addresses, localhost and this "
                         "machine's names, e.g. [\"moi-rig-3.factory.lan\"] (any other Host is refused)"),
    "display_unit": dict(doc="unit of inertia shown when a recipe names none (values stay kg·m²)",
                         choices=tuple(INERTIA_UNITS) + tuple(ASCII_NAMES)),
    "shift_starts": dict(doc="shift start times HH:MM, local time (Home counts the parts of the current shift)"),
    "users_file": dict(doc="named users with roles (operator, quality, admin) and password hashes, made by "
                       "`moi user add` (default: none; the token is the one login)", kind="path"),
    "max_streams": dict(doc="live streams (/events) at once, counted apart from max_connections; when all are "
                        "taken, an address holding fewer than its share (max_streams over the addresses) gets one "
                        "and the oldest stream of the address holding the most ends, a logged-in user's stream "
                        "ends the oldest anonymous one, else the newcomer is refused (503)", min=1, max=256),
    "max_streams_per_client": dict(doc="live streams at once from one address", min=1, max=256),
    "stream_lifetime": dict(doc="a live stream ends after this long (the browser opens a new one by itself), s",
                            min=1.0, max=86400.0),
    "time_format": dict(doc="how the pages write a time a person reads: strftime codes, the appliance's local "
                        "time (exports and the JSON API keep ISO 8601 with the UTC offset)"),
    "contact": dict(doc="whom the operator calls when the calibration is due or a check standard failed, or to "
                    "acknowledge a FAULT, e.g. \"quality lab, ext. 2345\" (said on the banner that refuses Measure, "
                    "on Home in FAULT, and in the refusal the push button, the PLC and MQTT get)"),
}


#: a shift start, HH:MM
_HHMM = re.compile(r"([01][0-9]|2[0-3]):[0-5][0-9]")


def _check(w: dict[str, Any], fail: Callable[[str, str], ConfigError]) -> None:
    w["display_unit"] = inertia_unit(w["display_unit"])
    for hm in w["shift_starts"]:
        if not _HHMM.fullmatch(str(hm)):
            raise fail("shift_starts", f"expected times HH:MM (00:00 … 23:59), got {hm!r}")
    if "%" not in w["time_format"] or len(w["time_format"]) > 64:
        raise fail("time_format", f"expected strftime codes such as \"%d.%m.%Y %H:%M\", got {w['time_format']!r}")


def _secrets(web: WebSettings) -> list[Check]:
    """The token file and the users file, read as the web page reads them at start (a token file not there yet
    is made at the first start unless it is named)."""
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


def _descriptors(web: WebSettings) -> dict[str, int]:
    # aiohttp accepts up to a backlog's worth beyond the cap before it closes any
    return {"web": 2 * web.max_connections + web.max_streams}


#: the configuration's ``[web]`` table: on (with its defaults) without the table
TABLE = PublisherTable(WebSettings, KEYS, enabled="serve the appliance's web page", on_without_table=True,
                       check=_check, start_checks=lambda web: [bindable(web.host, web.port, "web page port"),
                                                               *_secrets(web)],
                       descriptors=_descriptors, contact=lambda web: web.contact)
