"""The set-up page: the appliance's health, its running configuration in words (secrets masked, paths shown after
a login), the angle now, and the camera's region of interest: its snapshot and the quality role's form that sets
it."""

from __future__ import annotations

import asyncio
import datetime as dt
import logging
import math
import shutil
import time
from typing import Any, Mapping

from aiohttp import web

from measurement.errors import VisionError
from service import __version__
from service.errors import InputFileError
from service.settings import sensor_registry as sensors

from .. import quality as Q
from .pages import Family, Refused, read_form

log = logging.getLogger("moi.web")

#: keys whose values the set-up page never shows
SECRET_WORDS = ("password", "token", "secret")


def mask(obj: Any) -> Any:
    """``obj`` with the value of every key that names a secret replaced by ***."""
    if isinstance(obj, Mapping):
        return {k: ("***" if any(w in str(k).lower() for w in SECRET_WORDS) and v and not str(k).endswith("_file")
                    else mask(v)) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [mask(x) for x in obj]
    return obj


#: keys whose values name a file or a folder on the appliance: shown only to someone logged in
PATH_WORDS = ("file", "dir", "path", "port_name", "device")


def _words(v: Any) -> str:
    """A set-up value as a person reads it: yes/no, "not set", numbers without exponents, lists joined."""
    if v is None:
        return "not set"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, (int, float)):
        return Q.number(v, ".7g")
    if isinstance(v, (list, tuple)):
        return ", ".join(_words(x) for x in v) or "none"
    return str(v)


def setup_words(config: Mapping[str, Any], *, shown_paths: bool) -> list[tuple[str, list[tuple[str, str]]]]:
    """The running configuration as (section, [(setting, value in words)]) for the set-up page: nested tables
    flattened to "table › key", secrets already masked; without a login, paths are not shown."""
    out: list[tuple[str, list[tuple[str, str]]]] = []

    def walk(prefix: str, d: Mapping[str, Any], rows: list[tuple[str, str]]) -> None:
        for k, v in d.items():
            label = f"{prefix} › {k}" if prefix else str(k)
            label = label.replace("_", " ")
            if isinstance(v, Mapping):
                walk(label, v, rows)
            elif isinstance(v, (list, tuple)) and v and all(isinstance(x, Mapping) for x in v):
                for i, x in enumerate(v, 1):
                    walk(f"{label} {i}", x, rows)
            elif not shown_paths and v and any(w in str(k).lower() for w in PATH_WORDS):
                rows.append((label, "(shown after logging in)"))
            else:
                rows.append((label, _words(v)))

    for section, d in config.items():
        rows: list[tuple[str, str]] = []
        if isinstance(d, Mapping):
            walk("", d, rows)
        else:
            rows.append((str(section), _words(d) if shown_paths or not any(w in str(section) for w in PATH_WORDS)
                         else "(shown after logging in)"))
        out.append((str(section).replace("_", " "), rows))
    return out


class SetUpPages(Family):
    """``/setup``, ``/api/health``, ``/api/angle`` and the camera's ``/setup/snapshot.png`` and ``/setup/roi``."""

    def health(self) -> dict[str, Any]:
        app = self.app
        cfg = app.config
        out: dict[str, Any] = {"software_version": __version__, "device_id": cfg.device_id,
                               "simulated": cfg.simulated, "state": app.live_status().state,
                               "loop_iterations": app.loop_iterations, "last_loop_error": app.last_loop_error}
        out.update(app.publisher_health())
        try:
            du = shutil.disk_usage(cfg.state_dir)
            out["disk"] = {"path": str(cfg.state_dir), "free_bytes": du.free, "total_bytes": du.total}
        except OSError:
            out["disk"] = None
        n = app.notifier
        ping = n.last_watchdog_ping
        out["watchdog"] = {"period_s": n.watchdog_period,
                           "last_ping_s_ago": (time.monotonic() - ping) if ping is not None else None}
        out["measurements_stored"] = app.store.count() if app.store is not None else None
        store = app.store
        out["store"] = {"damage": store.damage, "write_failure": store.write_failure} if store is not None else None
        return out

    async def api_health(self, request: web.Request) -> web.Response:
        return web.json_response(self.health())

    async def setup(self, request: web.Request, status: int = 200, **ctx: Any) -> web.Response:
        devices = self.app.devices
        readable = devices is not None and getattr(devices.sensor, "read_position", None) is not None
        logged_in = self.pages.logged_in(request)
        return self.pages.page(request, "setup.html", status=status, title="Set-up", health=self.health(),
                               config=setup_words(mask(self.app.config.to_dict()), shown_paths=logged_in),
                               sensor=sensors.running(self.app.config).LABEL, readable=readable,
                               web=self.server.stats(), **self._camera_setup(request), **ctx)

    async def api_angle(self, request: web.Request) -> web.Response:
        """The angle now: the last sample while a measurement captures, else one read of the encoder."""
        seq = self.app.sequencer
        if seq is None or self.app.devices is None:
            raise Refused(503, "the appliance is not running its devices yet")
        if seq.busy:
            p = seq.progress(max(0, seq.progress(0)["next"] - 1))
            if p["angle"]:
                return web.json_response({"angle_rad": p["angle"][-1], "source": "capture"})
            raise Refused(409, "a measurement is starting; no sample yet")
        read = getattr(self.app.devices.sensor, "read_position", None)
        if read is None:
            raise Refused(404, "this angle sensor has no one-off read (a camera: use the snapshot)")
        loop = asyncio.get_running_loop()
        try:
            _, angle = await loop.run_in_executor(None, read)
        except Exception as exc:  # a sensor fault is the answer, not a server error
            raise Refused(503, f"angle read failed: {exc}") from None
        return web.json_response({"angle_rad": angle, "angle_deg": math.degrees(angle),
                                  "source": sensors.running(self.app.config).LABEL})

    # --- the camera's region of interest ----------------------------------------------------------------
    def _camera_setup(self, request: web.Request) -> dict[str, Any]:
        """What the set-up page shows of the camera's region of interest, and whether this login may set it."""
        kind = sensors.running(self.app.config)
        config, path = kind.camera_config(self.app.config), kind.camera_file(self.app.config)
        if config is None:
            return {}
        return {"roi": config.target.roi, "frame_size": (config.camera.width, config.camera.height),
                "camera_file": path, "may_set_roi": self.pages.may(request, "camera") and path is not None}

    async def camera_roi(self, request: web.Request) -> web.StreamResponse:
        """Set the camera's region of interest (x, y, w, h px; all empty: the whole frame; quality role): checked
        as a camera file is, written to the camera file in one step, used from the next capture, and one line
        appended to the camera audit log. Refused while a measurement runs; a wrong value is said on the page
        with what was typed."""
        from service.sources.camera import CAMERA_AUDIT_FILE, audit_camera, roi_from_typed, set_roi

        form = await read_form(request)
        source = await self.pages.authorise(request, form, "camera")
        kind = sensors.running(self.app.config)
        config, path = kind.camera_config(self.app.config), kind.camera_file(self.app.config)
        if config is None:
            raise Refused(404, "this appliance has no camera")
        if path is None:
            raise Refused(409, "the demo camera has no camera file: name one ([simulation] camera or "
                               "[hardware.camera] file) to set its region of interest")
        seq = self.app.sequencer
        if seq is not None and seq.busy:
            raise Refused(409, "a measurement is running: set the region when it is idle")
        typed = {k: str(form.get(k) or "")[:12] for k in ("x", "y", "w", "h")}
        loop = asyncio.get_running_loop()
        try:
            roi = roi_from_typed(typed, config.camera.width, config.camera.height)
            new, before = await loop.run_in_executor(None, set_roi, path, roi)
        except (VisionError, InputFileError) as exc:
            return await self.setup(request, status=400, roi_error=str(exc), roi_typed=typed)
        await asyncio.wrap_future(self.app.call_soon(lambda: self.app.use_camera(new)))
        line = await loop.run_in_executor(None, audit_camera, self.app.config.state_dir / CAMERA_AUDIT_FILE, source,
                                          path, before, roi, dt.datetime.now(dt.UTC).isoformat(timespec="seconds"))
        log.info("web: camera region of interest set: %s", line.strip())
        raise web.HTTPSeeOther("/setup#camera")

    async def snapshot(self, request: web.Request) -> web.Response:
        """One camera frame with the region of interest, the target found, the pivot and the angle axis (what
        `moi camera-check` draws: ``service.sources.marker_check``)."""
        kind = sensors.running(self.app.config)
        config = kind.camera_config(self.app.config)
        if config is None:
            raise Refused(404, "this appliance has no camera")
        seq, devices = self.app.sequencer, self.app.devices
        if seq is None or devices is None:
            raise Refused(503, "the appliance is not running its devices yet")

        def grab() -> Any:  # on the main loop: never while a measurement reads the camera
            if seq.busy:
                raise Refused(409, "a measurement is running: the camera is busy; try again when it is idle")
            image = kind.frame(devices.sensor)
            if image is None:
                raise Refused(404, "this camera sensor gives no single frames")
            return image

        try:
            image = await asyncio.wrap_future(self.app.call_soon(grab))
            loop = asyncio.get_running_loop()
            png = await loop.run_in_executor(None, lambda: _annotated_png(image, config))
        except Refused:
            raise
        except Exception as exc:
            raise Refused(503, f"camera snapshot failed: {exc}") from None
        return web.Response(body=png, content_type="image/png", headers={"Cache-Control": "no-store"})


def _annotated_png(frame: Any, config: Any) -> bytes:
    import cv2

    from service.sources.marker_check import check_image
    annotated, _report, _lines = check_image(frame, config)
    ok, buf = cv2.imencode(".png", annotated)
    if not ok:
        raise RuntimeError("PNG encoding failed")
    return buf.tobytes()
