"""``[web]``: the appliance's own web page (bind address, port, the token file for actions)."""

from __future__ import annotations

from dataclasses import dataclass

#: the name of the plot kept with each measurement in the store
PLOT_NAME = "plot.png"

#: the token file used when ``[web] token_file`` is not given: in the state directory, created on first start
DEFAULT_TOKEN_FILE_NAME = "web-token"


@dataclass(frozen=True)
class WebSettings:
    """host: the address the page is served on (127.0.0.1: this machine only; 0.0.0.0: every interface).
    port: TCP port (0: any free port, for tests). token_file: the file holding the password/token that every
    action (Measure, Abort, acknowledge) needs; None: ``<state_dir>/web-token``, made with a random token
    on first start. page_size: measurements per history page. max_connections: connections served at once
    (a newcomer beyond them is closed at once: the descriptors of the process stay with the measurement, the
    PLC and MQTT). request_timeout: a connection that has not sent a complete request this many seconds after
    it opened (or after its last answer) is closed, s. server_names: host names the page may be asked for
    besides an IP address, localhost and this machine's own names (a request naming another host in its Host
    header is refused: a DNS-rebinding page on a LAN browser could otherwise read every result). display_unit:
    the unit of inertia the pages, reports and exports show when the recipe names none (values stay kg·m²).
    shift_starts: when the shifts begin, "HH:MM" in the appliance's local time: Home counts the parts of the
    shift in progress. users_file: a TOML file of named users with roles and scrypt password hashes (``moi
    user add``): people log in by name and each result records who started it; None: the token is the one
    login."""

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
