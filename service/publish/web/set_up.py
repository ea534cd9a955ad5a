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
from service.parts.calibration import uncalibrated
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


#: keys whose values name a file or a folder on the appliance (besides the settings declared as paths): shown only
#: to someone logged in
PATH_WORDS = ("file", "dir", "directory", "path", "source")
#: the tables of the running configuration, in the order and with the titles of the page; the first ones open
TITLES = {"": "Appliance", "rig": "Rig", "recipes": "Recipes", "simulation": "Simulated rig", "hardware": "Hardware",
          "sequencer": "Sequencer", "identification": "Identification", "modbus": "Modbus", "web": "Web page",
          "mqtt": "MQTT", "opcua": "OPC UA", "sparkplug": "Sparkplug B"}
OPEN = ("", "rig", "recipes")
#: the appliance's own keys at the top of its configuration, as the page names them
TOP_LABELS = {"source": "configuration file", "device_id": "device ID", "state_dir": "state directory",
              "rig_path": "rig file", "simulated": "simulated rig"}
#: the units the settings' docs do not end with (the one table of them; the others are read from the docs,
#: the rig file's from ``measurement.rig.RIG_UNITS``, an effect's from its parameters)
UNITS = {("identification", "min_swings"): "swings", ("identification", "outlier_sigma"): "robust σ",
         ("identification", "robust_scale"): "robust σ", ("identification", "gap_periods"): "swing periods",
         ("hardware", "timeout"): "s", ("hardware", "counts_per_turn"): "counts per turn",
         ("modbus", "baudrate"): "Bd", ("hardware", "baudrate"): "Bd", ("rig", "mass"): "kg"}
#: what a setting's doc may end with as its unit ("…, s", "…, Hz of simulated time")
UNIT_WORDS = ("s", "ms", "rad", "rad/s", "kg·m²", "kg", "m", "Hz", "N·m/rad", "m/s²", "ppm", "degrees", "px",
              "bits per turn", "V", "%")


Rows = list[tuple[str, str]]
#: the configuration file's tables and their keys as declared (``ApplianceView.settings_schema``)
Schema = Mapping[str, Mapping[str, Any]]


def unit_in_doc(doc: str) -> str | None:
    """The unit a setting's doc says its value is in: its last comma-separated part (parenthesised notes left out)
    that is a unit, or starts with one ("Hz of simulated time"); None when it says none."""
    import re

    plain = re.sub(r"\([^()]*\)", "", doc)
    for part in reversed([p.strip() for p in plain.split(",")]):
        if part in UNIT_WORDS or part.split(" of ")[0] in UNIT_WORDS and " of " in part:
            return part.replace("degrees", "°")
    return None


def _unit(schema: Schema, table: str, path: tuple[str, ...]) -> str | None:
    """The unit of the setting at ``path`` in ``table`` (None: a count, a name, a yes/no, or not known)."""
    from measurement.effects import EFFECTS
    from measurement.rig import RIG_UNITS

    key = path[-1]
    if table == "rig":
        return RIG_UNITS.get(key)
    if table == "simulation" and len(path) == 3 and path[0] == "effects" and path[1] in EFFECTS:
        for prm in EFFECTS[path[1]].parameters:
            if key in (prm.physical, prm.name):
                return prm.physical_unit if key == prm.physical else prm.unit
    keys = schema.get(".".join((table, *path[:-1])), {})
    declared = keys[key].doc if key in keys else ""
    return unit_in_doc(declared) or UNITS.get((table, key))


def _is_path(schema: Schema, table: str, path: tuple[str, ...], v: Any) -> bool:
    """Whether a setting names a file, a folder or a device of the appliance: declared so, named so, or written
    as one."""
    keys = schema.get(".".join((table, *path[:-1])) if table else "device", {})
    key = path[-1]
    declared = key in keys and keys[key].kind in ("path", "videodevice")
    return bool(v) and (declared or any(w in PATH_WORDS for w in key.lower().split("_"))
                        or isinstance(v, str) and v.startswith(("/", "~", "./", "../")))


def _words(v: Any, unit: str | None = None) -> str:
    """A set-up value as a person reads it: yes/no, "not set", numbers without exponents and with their unit, lists
    joined."""
    if v is None:
        return "not set"
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, (int, float)):
        return Q.number(v, ".7g") + (f" {unit}" if unit else "")
    if isinstance(v, (list, tuple)):
        return ", ".join(_words(x, unit) for x in v) or "none"
    return str(v)




def _rows(schema: Schema, table: str, d: Mapping[str, Any], shown_paths: bool, path: tuple[str, ...] = ()) -> Rows:
    """One table's settings as (label, value in words): nested tables flattened to "table › key" (a rig file's own
    [rig] table to its keys), lists of tables numbered."""
    rows: Rows = []
    for k, v in d.items():
        at = (*path, str(k))
        label = " › ".join(p for p in at if not (table == "rig" and p == "rig")).replace("_", " ")
        if isinstance(v, Mapping):
            rows += _rows(schema, table, v, shown_paths, at)
        elif isinstance(v, (list, tuple)) and v and all(isinstance(x, Mapping) for x in v):
            for i, x in enumerate(v, 1):
                rows += [(f"{label} {i} › {sub}", text) for sub, text in _rows(schema, table, x, shown_paths)]
        elif not shown_paths and _is_path(schema, table, at, v):
            rows.append((label, "(shown after logging in)"))
        else:
            rows.append((label, _words(v, _unit(schema, table, at))))
    return rows


def setup_words(config: Mapping[str, Any], schema: Schema, *, shown_paths: bool) -> list[tuple[str, Rows, bool]]:
    """The running configuration for the set-up page, grouped: (title, [(setting, value in words with its unit)],
    open at first). The appliance's own keys first, with the tables not in use named there; secrets already masked;
    ``schema``: the file's tables as declared (their units, their paths); without a login, no file, folder or
    device path."""
    top: Rows = []
    off: list[str] = []
    groups: dict[str, Rows] = {}
    for section, d in config.items():
        if isinstance(d, Mapping):
            groups[section] = _rows(schema, section, d, shown_paths)
        elif section in TITLES and d is None:
            off.append(TITLES[section])
        else:
            hidden = not shown_paths and _is_path(schema, "", (section,), d)
            top.append((TOP_LABELS.get(section, section.replace("_", " ")),
                        "(shown after logging in)" if hidden else _words(d)))
    if off:
        top.append(("not in use", ", ".join(off)))
    order = [t for t in TITLES if t in groups] + [t for t in groups if t not in TITLES]
    return [(TITLES[""], top, True)] + [(TITLES.get(t, t.replace("_", " ")), groups[t], t in OPEN) for t in order]


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
        health = self.health()
        if health["disk"] is not None and not self.pages.logged_in(request):
            health["disk"].pop("path")  # no folder of the appliance to a visitor, as on the set-up page
        return web.json_response(health)

    async def setup(self, request: web.Request, status: int = 200, **ctx: Any) -> web.Response:
        devices = self.app.devices
        readable = devices is not None and getattr(devices.sensor, "read_position", None) is not None
        logged_in = self.pages.logged_in(request)
        return self.pages.page(request, "setup.html", status=status, title="Set-up", health=self.health(),
                               config=setup_words(mask(self.app.config.to_dict()), self.app.settings_schema(),
                                                  shown_paths=logged_in),
                               sensor=sensors.running(self.app.config).LABEL, readable=readable,
                               uncalibrated=uncalibrated(self.app.calibration_state()),
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
