"""The state directory a daemon runs on: its lock (one daemon per directory) and its result store, opened with
the reads a start does.

One daemon per state directory: a second one would take over the MQTT client id and deliver every result
twice. The lock is the kernel's (flock): it goes with the process, even after a kill -9.
"""

from __future__ import annotations

import fcntl
import logging
import os
from pathlib import Path
from typing import Callable

from service.errors import StartupError, StoreDamaged
from service.persistence.salvage import quarantine_store
from service.persistence.store import Store

log = logging.getLogger("moi.daemon")

#: the lock file in the state directory that makes a second daemon on it stop at start
LOCK_NAME = "moi.lock"


def lock_state_dir(state: Path) -> int:
    """Take the state directory's lock (the descriptor holds it; ``unlock_state_dir`` releases it); StartupError
    naming the process that holds it."""
    try:
        state.mkdir(parents=True, exist_ok=True)
        fd = os.open(state / LOCK_NAME, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o640)
    except OSError as exc:
        raise StartupError(f"cannot create the lock file in {str(state)!r}: {exc.strerror}") from None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        other = os.pread(fd, 32, 0).decode(errors="replace").strip() or "?"
        os.close(fd)
        raise StartupError(f"another moi daemon (pid {other}) runs on the state directory {str(state)!r}; "
                           "stop it first, or give this one its own state_dir") from None
    os.ftruncate(fd, 0)
    os.pwrite(fd, f"{os.getpid()}\n".encode(), 0)
    return fd


def unlock_state_dir(fd: int) -> None:
    """Release the lock ``lock_state_dir`` took (closing the descriptor releases it)."""
    os.close(fd)


def open_store(state_dir: Path, wall_clock: Callable[[], float]) -> Store:
    """The store, after the reads a start does; a damaged one is moved aside and what can be read is salvaged
    into a new one (a restart loop on a damaged file would stop the appliance for good, and deleting it would
    lose results). ``wall_clock``: Unix time, s (the name of the file moved aside)."""
    try:
        store = Store(state_dir)
        try:
            store.outbox_count()
            store.latest("ok")
            store.outbox_pending(limit=10)
        except BaseException:
            store.close()
            raise
        return store
    except StoreDamaged as exc:
        log.error("%s", exc)
    aside, health = quarantine_store(state_dir, wall_clock)
    log.error("the damaged result store was moved to %s; a new store holds what could be read (%s)", aside,
              health.summary())
    return Store(state_dir)
