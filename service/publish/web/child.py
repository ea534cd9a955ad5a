"""What a browser may ask for that takes more than a moment: done in a child process, one job at a time.

The sensor of a capture is read by threads of the daemon's process (the
encoder's Modbus client, the camera's frame reader). Work done by any other
thread of that process holds the interpreter lock against them: four clients
looping on the history export dropped an encoder capture from some 140 to 10
samples/s and spoiled its J, while two busy processes on both cores did not.
So the exports, a trace as CSV and a plot drawn again from a stored trace run
in one child process (started on first use, at a lower priority); the web
loop only awaits them, and a request beyond ``max_waiting`` queued jobs is
told to come back later.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import logging
import multiprocessing
import os
import select
import threading
import time
from concurrent.futures.process import BrokenProcessPool
from typing import Any, Callable, Mapping

log = logging.getLogger("moi.web")

#: jobs queued or running at once; one more is refused (the web answers 503)
MAX_WAITING = 4
#: how much lower the child runs than the daemon (nice increment): the capture comes first on a busy core
CHILD_NICENESS = 10


class ChildBusy(Exception):
    """``max_waiting`` jobs are already queued."""


class ChildWork:
    """One child process for the heavy answers of the web page (``run`` from the web loop, ``call`` from a thread)."""

    def __init__(self, max_waiting: int = MAX_WAITING) -> None:
        self.max_waiting = max_waiting
        self._pool: concurrent.futures.ProcessPoolExecutor | None = None
        self._lock = threading.Lock()
        self._waiting = 0
        self.jobs = 0

    def _submit(self, fn: Callable[..., Any], *args: Any) -> concurrent.futures.Future:
        with self._lock:
            if self._waiting >= self.max_waiting:
                raise ChildBusy(f"{self._waiting} exports or plots are being made; try again in a moment")
            if self._pool is None:
                # spawn, not fork: the daemon's threads hold locks a forked child would inherit held
                self._pool = concurrent.futures.ProcessPoolExecutor(
                    max_workers=1, mp_context=multiprocessing.get_context("spawn"), initializer=_in_child,
                    initargs=(os.getpid(),))
            pool = self._pool
            self._waiting += 1
            self.jobs += 1
        try:
            fut = pool.submit(fn, *args)
        except BaseException:
            self._done(None)
            raise
        fut.add_done_callback(self._done)
        return fut

    def _done(self, fut: concurrent.futures.Future | None) -> None:
        with self._lock:
            self._waiting -= 1
            if fut is not None and not fut.cancelled() and isinstance(fut.exception(), BrokenProcessPool):
                log.error("the web page's child process died; a new one is started for the next job")
                self._pool = None

    async def run(self, fn: Callable[..., Any], *args: Any) -> Any:
        """``fn(*args)`` in the child (``fn`` and the arguments picklable); ChildBusy when too many wait."""
        return await asyncio.wrap_future(self._submit(fn, *args))

    def call(self, fn: Callable[..., Any], *args: Any) -> Any:
        """``fn(*args)`` in the child, waiting for it on the calling thread."""
        return self._submit(fn, *args).result()

    def close(self) -> None:
        """End the child (a job in progress finishes first); safe twice."""
        with self._lock:
            pool, self._pool = self._pool, None
        if pool is not None:
            pool.shutdown(wait=True, cancel_futures=True)


def _in_child(daemon: int) -> None:
    """The child's set-up: a lower priority, and its end when the daemon ends."""
    with contextlib.suppress(OSError):  # not allowed here: the job still runs, at the daemon's priority
        os.nice(CHILD_NICENESS)
    threading.Thread(target=_end_with, args=(daemon,), name="moi-child-lifeline", daemon=True).start()


def _end_with(daemon: int) -> None:
    """End this process when the process ``daemon`` ends, however it ends. Killed (kill -9, the OOM killer), the
    daemon closes nothing: the child would wait for jobs for ever, and multiprocessing's resource tracker, which
    ends when no process holds its pipe any more, with it. Not a parent-death signal (prctl): that follows the
    thread that started the child, and the web loop's thread is not the daemon."""
    try:
        watch: int | None = os.pidfd_open(daemon)  # readable once the process has ended (Linux 5.3)
    except ProcessLookupError:
        watch = None  # already gone
    except OSError:  # an older kernel: the parent's id, which becomes the reaper's when the daemon ends
        while os.getppid() == daemon:
            time.sleep(1.0)
        watch = None
    if watch is not None:
        select.select([watch], [], [])
    os._exit(0)


# --- the jobs (run in the child: module-level functions of plain arguments) -------------------------------------

def export_file(state_dir: str, fmt: str, filters: Mapping[str, Any]) -> bytes:
    """The history as ``moi export`` writes it (CSV or JSON, oldest first), of the measurements ``filters`` select;
    "dfq": the AQDEF file of the recipe's completed parts."""
    from service.persistence.store import Store
    from service.publish.export import csv_text, json_text

    with Store(state_dir, read_only=True) as store:
        if fmt == "dfq":
            from service.publish.export import dfq_bytes

            return dfq_bytes(store, filters.get("recipe"), part_id=filters.get("part_id"), since=filters.get("since"),
                             until=filters.get("until"))
        rows, _ = store.search(limit=None, **filters)
    rows.reverse()
    return (json_text(rows) if fmt == "json" else csv_text(rows)).encode()


def trace_file(state_dir: str, uuid: str) -> bytes:
    """The stored trace of the measurement ``uuid`` as trace CSV (``moi export --trace``)."""
    from service.persistence.store import Store
    from service.publish.export import trace_text

    with Store(state_dir, read_only=True) as store:
        m = store.get(uuid, trace=True)
    return trace_text(m).encode()


def replot(state_dir: str, uuid: str, default_rig: Mapping[str, Any], options: Any, simulated: bool = False,
           default_unit: str = "kg·m²") -> bytes:
    """The plot of the measurement ``uuid`` (PNG) from its stored trace, identified again with its rig."""
    from measurement import Rig, Trace, identify
    from service.persistence.store import Store
    from service.publish.payload import stored_result
    from service.publish.plot import render_png

    from ..quality import plot_labels

    with Store(state_dir, read_only=True) as store:
        m = store.get(uuid, trace=True)
    rig = Rig.from_dict(m.rig or default_rig)
    unit, source = plot_labels(m, stored_result(m.payload), simulated, default_unit)
    return render_png(identify(Trace(m.trace_t, m.trace_angle, source=f"measurement {m.seq}"), rig, options),
                      unit=unit, source=source)


def report_file(state_dir: str, uuid: str, default_unit: str, time_format: str | None = None,
                decimals: int | None = None) -> bytes:
    """The report of the measurement ``uuid`` as PDF (``moi report ID --pdf``)."""
    from service.parts.gauge_study import study_releases
    from service.persistence.store import Store
    from service.publish.report import report_pdf

    from ..quality import display_unit
    from .settings import PLOT_NAME

    with Store(state_dir, read_only=True) as store:
        m = store.get(uuid)
        got = store.get_attachment(uuid, PLOT_NAME)
        counted = study_releases(store, state_dir).get(m.uuid)
        return report_pdf(m, got[0] if got else None, display_unit(m.payload, default_unit), store.get,
                          decimals=decimals, study=counted.words if counted else None,
                          **({"time_format": time_format} if time_format else {}))


def grr_file(state_dir: str, recipe: str, study: Mapping[str, Any], unit: str, shown: Mapping[str, Any],
             time_format: str, device_id: str) -> bytes:
    """The Gauge R&R of ``recipe`` from the store's records as PDF: the page's study (``study``: the keyword
    arguments of ``recipe_grr``), in ``unit`` with the recipe's decimals (``shown``)."""
    from service.parts.gauge_rr import recipe_grr
    from service.persistence.store import Store
    from service.publish.grr_report import grr_pdf
    from service.publish.grr_view import grr_view

    with Store(state_dir, read_only=True) as store:
        g = recipe_grr(store, recipe, **study)
    return grr_pdf(grr_view(g, unit, shown, time_format), device_id, time_format)
