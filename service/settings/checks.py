"""A finding of `moi run --check` and the probes every table's checks share: a file that can be read, a port that
can be bound. The assembler's own checks (``service.config.check``) and each publisher's (its table's
``start_checks``) make them."""

from __future__ import annotations

import os
import socket
from dataclasses import dataclass
from pathlib import Path


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


def readable(path: str | None, what: str) -> Check | None:
    """Whether the file ``path`` exists and this user can read it (None: no file named)."""
    if not path:
        return None
    p = Path(path)
    if not p.is_file():
        return Check(what, False, f"{path} does not exist or is not a file")
    if not os.access(p, os.R_OK):
        return Check(what, False, f"{path} is not readable by this user")
    return Check(what, True, str(path))


def readable_files(files: tuple[tuple[str | None, str], ...]) -> list[Check]:
    """``readable`` of each (path, what) that names a file."""
    return [c for path, what in files if (c := readable(path, what)) is not None]


def bindable(host: str, port: int, what: str) -> Check:
    """Whether a server can listen on ``host:port`` now (port 0: any free one)."""
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
