"""The OPC UA server (asyncua): the appliance as a machine of OPC 40001-1 Machinery, its results after
OPC 40001-101 Machinery Result Transfer, on the specifications' types (``model``: modelled in their
namespaces with their NodeIds; why not loaded from the NodeSet2 files: docs/opcua.md).

Address space (browse names; the namespace of each in brackets; the type definition after the colon):

    Objects/Machines [Machinery]/<device id> [moi]
        Identification [DI]: MachineIdentificationType (Manufacturer, Model, SerialNumber, SoftwareRevision,
            ProductInstanceUri)
        MachineryBuildingBlocks [Machinery]: FolderType (HasAddIn: Identification and the three below)
            MachineryItemState [Machinery]: MachineryItemState_StateMachineType
                CurrentState: NotAvailable | OutOfService | NotExecuting | Executing
            MachineryOperationMode [Machinery]: MachineryOperationModeStateMachineType
                CurrentState: None | Maintenance | Setup | Processing
            ResultManagement [Result]: ResultManagementType; GetResultById, GetLatestResult,
                AcknowledgeResults; Results/LatestResult: ResultType (a ResultDataType); raises
                InertiaResultReadyEventType [moi], a ResultReadyEventType [Result], per result.

The server runs on its own asyncio loop in a thread (``drivers.aioloop.LoopThread``); the daemon's hooks
hand it work and never wait for it. What the clients acknowledged is kept in the state directory
(``service.persistence.acks``, as the Modbus FIFO keeps the PLC's).
"""

from __future__ import annotations

import asyncio
import contextlib
import dbm
import gc
import importlib
import logging
import math
import time
from collections import OrderedDict
from datetime import datetime
from pathlib import Path
from typing import Any, Mapping

from asyncua import Node, Server, ua

from drivers.aioloop import LoopThread
from service.errors import ConfigError, OpcUaServerError
from service.parts.outcome import PartOutcome
from service.persistence.acks import AckFile, AckState
from service.publish.port import ApplianceView, Publisher
from service.states import STATES

from .guard import Guard, GuardedServer, Limits
from .machine import EMPTY, VTYPES, add_machine
from .model import CONTENT_FIELDS, META_COMPONENTS, RESULT_EVALUATION, Model, install, register_result_data_type
from .security import Users, secure
from .settings import OpcUaSettings

log = logging.getLogger("moi.opcua")

#: the appliance's state → MachineryItemState (OPC 40001-1)
ITEM_STATES: dict[str, str] = {
    "STARTING": "NotAvailable", "STOPPING": "NotAvailable", "FAULT": "OutOfService",
    "IDLE": "NotExecuting", "ABORTED": "NotExecuting",
    "ARMED": "Executing", "RELEASING": "Executing", "CAPTURING": "Executing", "IDENTIFYING": "Executing",
    "PUBLISHING": "Executing",
}

#: the file in the state directory that keeps what the OPC UA clients acknowledged (``service.persistence.acks``)
ACKED_FILE = "opcua-acked"

#: the method's wait for a result is limited to this, ms
MAX_TIMEOUT_MS = 60_000

#: AcknowledgeResults' error per ResultId (values < 0: application-specific, OPC 40001-101): no result has this
#: ResultId; the result awaits no acknowledgement (acknowledged already, or older than the results_kept offered)
ACK_UNKNOWN, ACK_ALREADY = -1, -2


def operation_mode(state: str, check_standard: bool, calibration_due: bool) -> str:
    """MachineryOperationMode (OPC 40001-1: None, Maintenance, Setup, Processing) from the appliance's state.

    None while the appliance starts or stops (no mode is available); Maintenance while the active recipe
    measures a check standard (the rig is verified, no part is measured); Setup while the rig's calibration is
    due (past its validity, or its newest check standard failed: results are flagged calibration_due until
    it is calibrated again or a check standard passes); Processing otherwise (parts are measured)."""
    if state in ("STARTING", "STOPPING"):
        return "None"
    if check_standard:
        return "Maintenance"
    return "Setup" if calibration_due else "Processing"


def fast_dbm() -> bool:
    """Whether Python's dbm has a backend other than dbm.dumb (gdbm, ndbm; sqlite3 from Python 3.13). asyncua
    keeps its cache of the standard address space in a shelf: read from gdbm or ndbm, a start takes some 20 ms
    of CPU for what building it from code takes 0.9 s (on a PC); read from dbm.dumb, 1.6 s: then no cache."""
    for name in getattr(dbm, "_names", ()):
        if name != "dbm.dumb":
            try:
                importlib.import_module(name)
                return True
            except ImportError:
                continue
    return False


def result_evaluation(outcome: PartOutcome) -> str:
    """The verdict as ResultEvaluation: OK → OK, NOK → NotOK, INVALID or inside the guard band's uncertainty
    range → NotDecidable; no verdict (no recipe, part incomplete) → Undefined. The part's decision once the
    release completes it, else the release's."""
    verdict = outcome.shown_verdict
    if verdict is not None and outcome.not_decidable:
        return "NotDecidable"
    return {"OK": "OK", "NOK": "NotOK"}.get(verdict or "", "Undefined")


def _num(v: Any) -> float | None:
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) else None


def _time(text: Any) -> datetime | None:
    try:
        return datetime.fromisoformat(str(text).replace("Z", "+00:00")) if text else None
    except ValueError:
        return None


def result_document(payload: Mapping[str, Any]) -> dict[str, Any]:
    """A result's ResultMetaData and ResultContent as plain values (unknown numbers None), from which the
    ResultDataType is made (``OpcUaServer._structure``)."""
    outcome = PartOutcome.from_dict(payload)
    recipe = outcome.recipe or {}
    made = outcome.decision
    timing = payload.get("timing") or {}
    meta = {
        "ResultId": payload.get("uuid"),
        "CreationTime": payload.get("finished_at"),
        "StartTime": payload.get("started_at"),
        "AcquisitionDuration": _num(timing.get("capture_s")),
        "ProcessingDuration": _num(timing.get("capture_to_result_s")),
        "ProductId": recipe.get("name"),
        "PartId": outcome.part_id,
        "ExternalRecipeId": recipe.get("name"),
        "ResultEvaluation": result_evaluation(outcome),
        "SequenceNumber": payload.get("seq"),
    }
    content = {
        "J": _num(payload.get("J")),
        # the expanded uncertainty of J where the result carries it; J_u, the combined standard uncertainty
        # (fit ⊕ calibration ⊕ model form), always; U: the verdict's expanded uncertainty (with a recipe)
        "J_U": _num(payload.get("J_U")),
        "J_u": _num(payload.get("J_u")),
        "U": _num(made.U if made is not None else None),
        "omega_n": _num(payload.get("omega_n")),
        "damping_ratio": _num(payload.get("damping_ratio")),
        "flags": list(payload.get("flags") or ()),
        "verdict": outcome.shown_verdict,
    }
    return {"ResultMetaData": meta, "ResultContent": content}


class OpcUaServer(Publisher):
    """The OPC UA server; ``start()`` returns once it listens."""

    NAME = "opcua"

    def __init__(self, settings: OpcUaSettings, device_id: str, state_dir: Path, *, software_version: str = "",
                 store: Any = None, simulated: bool = False) -> None:
        self.settings = settings
        self.device_id = device_id
        self.state_dir = Path(state_dir)
        self.software_version = software_version
        self.store = store
        self.simulated = simulated
        self.password = self._password()
        self._io = LoopThread("moi-opcua")
        self._server: Server | None = None
        self.bound_port: int | None = None
        self.start_seconds: float | None = None  # how long the last start took, s
        self.types_seconds: float | None = None  # of which the companion specifications' types, s
        self._model: Model | None = None
        self._types: dict[str, Any] = {}  # the Python classes of the structures (asyncua makes them at start)
        self._results: OrderedDict[str, dict[str, Any]] = OrderedDict()  # uuid → document, newest last
        self._unacknowledged: OrderedDict[str, int] = OrderedDict()  # uuid → seq, oldest first
        self._acks = AckFile(self.state_dir / ACKED_FILE)
        self._acked_through = 0  # every result up to this seq acknowledged but those in _unacknowledged
        self._ack_lock: asyncio.Lock | None = None
        self._latest: dict[str, Any] | None = None  # the newest result's document (the store's, at start)
        self._new_result: asyncio.Event | None = None
        self._nodes: dict[str, Node] = {}
        self._event: Any = None
        self._state = "STARTING"
        self._check_standard = False
        self._calibration_due = False
        self._mode = "None"
        self.events_sent = 0
        self.guard = Guard(Limits(max_connections=settings.max_connections, login_timeout=settings.login_timeout,
                                  max_nodes_per_request=settings.max_nodes_per_request),
                           capturing=lambda: STATES.get(self._state, STATES["STARTING"]).capturing)

    def _password(self) -> str | None:
        s = self.settings
        if s.password_file:
            try:
                return Path(s.password_file).read_text(encoding="utf-8").strip()
            except OSError as exc:
                raise ConfigError(f"[opcua] password_file {s.password_file!r} cannot be read: {exc.strerror}") from None
        return s.password

    def _path(self, configured: str | None, default: str) -> Path:
        return Path(configured) if configured else self.state_dir / "opcua" / default

    # --- lifecycle -----------------------------------------------------------------------------
    def start(self, timeout: float = 120.0) -> None:
        """Serve; returns once the port is bound (OpcUaServerError when it cannot). The first start builds
        the standard address space cache and the certificate (tens of seconds on a Pi); later ones read them."""
        t0 = time.monotonic()
        try:
            self._io.start_serving(self._main(), timeout)
        except TimeoutError:
            raise OpcUaServerError(f"the OPC UA server did not start within {timeout:g} s") from None
        except OpcUaServerError:
            raise
        except OSError as exc:
            raise OpcUaServerError(f"cannot listen on OPC UA {self.settings.host}:{self.settings.port} "
                                   f"({exc.strerror or exc})") from None
        self.start_seconds = time.monotonic() - t0
        log.info("OPC UA server on %s (started in %.2f s)", self.endpoint, self.start_seconds)

    @property
    def endpoint(self) -> str:
        return f"opc.tcp://{self.settings.host}:{self.bound_port or self.settings.port}/moi/"

    async def _main(self) -> None:
        s = self.settings
        cache = self._path(s.cache_file, "address-space") if fast_dbm() else None
        cert = self._path(s.certificate, "server-cert.der")
        key = self._path(s.private_key, "server-key.pem")
        for p in (cache, cert, key):
            if p is not None:
                p.parent.mkdir(mode=0o700, parents=True, exist_ok=True)  # the key is never readable by others
        server = GuardedServer(self.guard, user_manager=Users(s.username, self.password, s.anonymous, self.guard))
        await server.init(cache)
        # asyncua's standard address space is some 0.5 M Python objects that live as long as the server: out of
        # the collector's generations (unfrozen at stop), no full collection walks them again (one took a third
        # of a second of each start on a PC, while the types were added)
        gc.freeze()
        server.set_endpoint(f"opc.tcp://{s.host}:{s.port}/moi/")
        server.set_server_name(f"moi {self.device_id}")
        await secure(server, s, self.device_id, cert, key)
        self._ack_lock = asyncio.Lock()
        await asyncio.to_thread(self._restore)
        await self._build(server)
        self._new_result = asyncio.Event()
        await server.start()
        self._server = server
        bserver = server.bserver
        self.bound_port = getattr(bserver, "port", None) if bserver is not None else None

    def _restore(self) -> None:
        """What the clients had not acknowledged before the restart (the newest ``results_kept``), from the
        store, and the newest result for LatestResult. The first start (no file kept) owes nothing older
        than the results stored from now on."""
        kept = max(1, self.settings.results_kept)
        # newest first: the newest is LatestResult's
        recent = self.store.list(limit=kept, status="ok", full=True) if self.store is not None else []
        latest = recent[0] if recent else None
        state = self._acks.read()
        if state is None:
            state = AckState(latest.seq if latest is not None else 0)
            self._keep(state)
        rows: dict[int, Any] = {}
        if self.store is not None:
            for r in recent:
                if r.seq > state.through:
                    rows[r.seq] = r
            for seq in sorted(state.pending)[-kept:]:
                r = self.store.get(seq)
                if r is not None and r.seq == seq and r.status == "ok":
                    rows[seq] = r
        for seq in sorted(rows)[-kept:]:
            r = rows[seq]
            if r.payload is not None:
                self._results[r.uuid] = result_document(r.payload)
                self._unacknowledged[r.uuid] = seq
        self._acked_through = state.through
        if latest is not None and latest.payload is not None:
            self._latest = self._results.get(latest.uuid) or result_document(latest.payload)
            self._results.setdefault(latest.uuid, self._latest)

    def _keep(self, state: AckState) -> None:
        try:
            self._acks.write(state)
        except OSError as exc:  # the acknowledgement holds; only a restart would offer the result again
            log.warning("OPC UA: cannot keep the acknowledged results in %s: %s", self._acks.path, exc)

    async def _build(self, server: Server) -> None:
        t0 = time.monotonic()
        model = self._model = await install(server)
        await server.load_data_type_definitions()  # the Python classes of the structures (ua.ResultDataType ...)
        register_result_data_type(model)  # ResultDataType as the specification encodes it
        self.types_seconds = time.monotonic() - t0
        self._types = {name: getattr(ua, name) for name in ("ResultDataType", "ResultMetaDataType",
                                                             "ProcessingTimesDataType", "InertiaResultDataType",
                                                             "ResultEvaluationEnum")}
        s = self.settings
        serial = s.serial_number or self.device_id
        identity = {"Manufacturer": ua.LocalizedText(s.manufacturer), "Model": ua.LocalizedText(s.model),
                    "SerialNumber": serial, "SoftwareRevision": self.software_version,
                    "ProductInstanceUri": f"urn:moi:{s.manufacturer}:{serial}"}
        methods = {"GetResultById": self._get_by_id, "GetLatestResult": self._get_latest,
                   "AcknowledgeResults": self._acknowledge}
        self._nodes.update(await add_machine(server, model, self.device_id, identity, methods,
                                             unacknowledged=len(self._unacknowledged)))
        await self._write_state("item", ITEM_STATES[self._state])
        await self._write_state("mode", self._mode)
        if self._latest is not None:
            await self._write_latest(self._structure(self._latest))
        self._event = await server.get_event_generator(model.nodes["InertiaResultReadyEventType"],
                                                       self._nodes["result_management"].nodeid)

    def stop(self, timeout: float = 5.0) -> None:
        if not self._io.running:
            return
        if self._server is not None:
            try:
                self._io.call(self._server.stop(), timeout)
            except Exception as exc:  # stopping: nothing else to do but say so
                log.warning("OPC UA server stop: %s", exc)
            self._server = None
        self._io.stop(timeout)
        gc.unfreeze()

    def failure(self) -> str | None:
        return None if self._io.running else "the OPC UA server thread stopped"

    def where(self) -> str:
        return f"OPC UA {self.endpoint}"

    def capture_requests(self) -> int:
        return self.guard.gated + self.guard.connected_in_capture

    def health(self) -> dict[str, Any]:
        return {"endpoint": self.endpoint, "results_unacknowledged": len(self._unacknowledged),
                "events_sent": self.events_sent, "start_seconds": self.start_seconds,
                "operation_mode": self._mode} | self.guard.health()

    # --- the ResultDataType ----------------------------------------------------------------------
    def _structure(self, doc: Mapping[str, Any]) -> Any:
        """A result document as ResultDataType: ResultMetaDataType and, in ResultContent, one
        InertiaResultDataType."""
        T = self._types
        m, c = doc["ResultMetaData"], doc["ResultContent"]
        start, end = _time(m.get("StartTime")), _time(m.get("CreationTime"))
        times = None
        if start is not None and end is not None:
            times = T["ProcessingTimesDataType"](
                StartTime=start, EndTime=end,
                AcquisitionDuration=None if m.get("AcquisitionDuration") is None else 1000 * m["AcquisitionDuration"],
                ProcessingDuration=None if m.get("ProcessingDuration") is None else 1000 * m["ProcessingDuration"])
        meta = T["ResultMetaDataType"](
            ResultId=str(m["ResultId"]), IsSimulated=self.simulated, ResultState=1,  # 1: Completed
            PartId=m.get("PartId"), ExternalRecipeId=m.get("ExternalRecipeId"), ProductId=m.get("ProductId"),
            CreationTime=end, ProcessingTimes=times,
            ResultEvaluation=T["ResultEvaluationEnum"](RESULT_EVALUATION[m["ResultEvaluation"]]))
        content = T["InertiaResultDataType"](
            SequenceNumber=int(m.get("SequenceNumber") or 0) & 0xFFFFFFFF,
            **{name: math.nan if c[name] is None else c[name]
               for name in ("J", "J_U", "J_u", "U", "omega_n", "damping_ratio")},
            Flags=[str(f) for f in c["flags"]], Verdict=c.get("verdict") or "")
        return T["ResultDataType"](ResultMetaData=meta, ResultContent=[ua.Variant(content)])

    # --- methods (the server's loop) --------------------------------------------------------------
    @staticmethod
    def _int32(v: Any) -> int | None:
        value = getattr(v, "Value", v)
        return value if isinstance(value, int) and not isinstance(value, bool) else None

    def _outputs(self, doc: Mapping[str, Any]) -> list[ua.Variant]:
        # ResultHandle 0: ReleaseResultHandle is not offered (OPC 40001-101); Error 0: OK
        return [ua.Variant(0, ua.VariantType.UInt32), ua.Variant(self._structure(doc)),
                ua.Variant(0, ua.VariantType.Int32)]

    async def _get_latest(self, parent: ua.NodeId, *args: Any) -> Any:
        if len(args) != 1 or (timeout := self._int32(args[0])) is None:
            return _bad(ua.StatusCodes.BadInvalidArgument)
        if self._latest is None and timeout > 0 and self._new_result is not None:
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self._new_result.wait(), min(timeout, MAX_TIMEOUT_MS) / 1000)
        if self._latest is None:
            return _bad(ua.StatusCodes.BadNoData)
        return self._outputs(self._latest)

    async def _get_by_id(self, parent: ua.NodeId, *args: Any) -> Any:
        result_id = getattr(args[0], "Value", None) if args else None
        if len(args) not in (1, 2) or not isinstance(result_id, str) or not result_id or (
                len(args) == 2 and self._int32(args[1]) is None):
            return _bad(ua.StatusCodes.BadInvalidArgument)
        doc = self._results.get(result_id)
        if doc is None:
            stored = await self._stored(result_id)
            if stored is not None and stored.payload is not None:
                doc = result_document(stored.payload)
        if doc is None:
            return _bad(ua.StatusCodes.BadNotFound)
        return self._outputs(doc)

    async def _stored(self, result_id: str) -> Any:
        """The stored result with this ResultId (a uuid), or None."""
        if self.store is None or len(result_id) != 36:
            return None
        stored = await asyncio.to_thread(self.store.get, result_id)
        return stored if stored is not None and stored.uuid == result_id else None

    async def _acknowledge(self, parent: ua.NodeId, *args: Any) -> Any:
        ids = getattr(args[0], "Value", None) if len(args) == 1 else None
        if not isinstance(ids, list) or not ids or not all(isinstance(i, str) and i for i in ids):
            return _bad(ua.StatusCodes.BadInvalidArgument)  # nothing is acknowledged
        assert self._ack_lock is not None
        async with self._ack_lock:  # one acknowledgement at a time, kept in the order given
            errors = []
            for i in ids:
                seq = self._unacknowledged.pop(i, None)
                if seq is not None:
                    self._acked_through = max(self._acked_through, seq)
                    errors.append(0)
                else:
                    errors.append(ACK_ALREADY if i in self._results or await self._stored(i) is not None else ACK_UNKNOWN)
            if 0 in errors:
                state = AckState(self._acked_through, frozenset(
                    s for s in self._unacknowledged.values() if s <= self._acked_through))
                await asyncio.to_thread(self._keep, state)
                await self._nodes["unacknowledged"].write_value(
                    ua.Variant(len(self._unacknowledged), ua.VariantType.UInt32))
        ok = all(e == 0 for e in errors)
        return [ua.Variant([] if ok else errors, ua.VariantType.Int32), ua.Variant(0 if ok else -1, ua.VariantType.Int32)]

    # --- the daemon's hooks (main loop thread: hand over, never wait) ---------------------------------
    def _submit(self, coro: Any) -> None:
        if not self._io.running:
            coro.close()
            return
        fut = self._io.submit(coro)
        fut.add_done_callback(_log_failure)

    def on_state(self, message: Mapping[str, Any], event: Any) -> None:
        state = str(message.get("state") or "")
        if state and state != self._state:
            self._state = state
            self._submit(self._write_state("item", ITEM_STATES.get(state, "NotAvailable")))
            self._update_mode()

    def on_recipe(self, recipe: Any) -> None:
        self._check_standard = recipe is not None and getattr(recipe, "check_standard", None) is not None
        self._update_mode()

    def on_live(self, live: Any) -> None:
        if bool(live.calibration_due) != self._calibration_due:
            self._calibration_due = bool(live.calibration_due)
            self._update_mode()

    def _update_mode(self) -> None:
        mode = operation_mode(self._state, self._check_standard, self._calibration_due)
        if mode != self._mode:
            self._mode = mode
            self._submit(self._write_state("mode", mode))

    async def _write_state(self, machine: str, state: str) -> None:
        if f"{machine}.state" not in self._nodes or self._model is None:
            return  # before the address space exists: _build writes the current one
        await self._nodes[f"{machine}.state"].write_value(ua.LocalizedText(state))
        await self._nodes[f"{machine}.id"].write_value(self._model.state_id(machine, state))

    def on_result(self, stored: Any, measurement: Any) -> None:
        if stored.payload is not None:
            self.publish_result(stored.payload)

    def publish_result(self, payload: Mapping[str, Any]) -> None:
        """A stored result: LatestResult, the results the methods read, unacknowledged until a client
        acknowledges it, and a ResultReadyEvent."""
        self._submit(self._publish(result_document(payload)))

    async def _write_latest(self, value: Any) -> None:
        """LatestResult and its components from a result as ResultDataType (``_structure``)."""
        meta, content = value.ResultMetaData, value.ResultContent[0].Value
        await self._nodes["latest"].write_value(ua.Variant(value))
        await self._nodes["latest.meta"].write_value(ua.Variant(meta))
        # ExtensionObject[], not the structure's Variant[]: both are BaseDataType[], and a client decodes the first
        # as it decodes any structure (node-opcua leaves an ExtensionObject inside a Variant array undecoded)
        await self._nodes["latest.content"].write_value(ua.Variant([content], ua.VariantType.ExtensionObject))
        for name, (_, vtype) in META_COMPONENTS.items():
            v = getattr(meta, name)
            v = EMPTY[vtype] if v is None else int(v) if name == "ResultEvaluation" else v
            await self._nodes[f"meta.{name}"].write_value(ua.Variant(v, vtype))
        for name, dt, _, _, _ in CONTENT_FIELDS:
            await self._nodes[f"content.{name}"].write_value(ua.Variant(getattr(content, name), VTYPES[dt]))

    async def _publish(self, doc: dict[str, Any]) -> None:
        meta = doc["ResultMetaData"]
        rid = str(meta["ResultId"])
        kept = max(1, self.settings.results_kept)
        self._results[rid] = doc
        while len(self._results) > kept:
            self._results.popitem(last=False)
        self._unacknowledged[rid] = int(meta.get("SequenceNumber") or 0)
        while len(self._unacknowledged) > kept:
            self._unacknowledged.popitem(last=False)  # given up: a restart does not offer it again either
        self._latest = doc
        value = self._structure(doc)
        await self._write_latest(value)
        await self._nodes["unacknowledged"].write_value(ua.Variant(len(self._unacknowledged), ua.VariantType.UInt32))
        ev = self._event
        ev.event.Result = value
        ev.event.Severity = 500 if meta["ResultEvaluation"] in ("NotOK", "NotDecidable") else 100
        await ev.trigger(message=f"result {meta.get('SequenceNumber')}: {meta['ResultEvaluation']}")
        self.events_sent += 1
        if self._new_result is not None:
            self._new_result.set()

    # --- the publisher port ---------------------------------------------------------------------------
    @classmethod
    def build(cls, settings: OpcUaSettings, appliance: ApplianceView) -> "OpcUaServer":
        cfg = appliance.config
        server = cls(settings, cfg.device_id, cfg.state_dir, software_version=appliance.software_version,
                     store=appliance.store, simulated=bool(cfg.simulated))
        server.on_recipe(appliance.parts.recipe)
        return server


def _bad(code: int) -> ua.StatusCode:
    """A method's Bad status code (the client's call raises it)."""
    return ua.StatusCode(ua.UInt32(code))


def _log_failure(fut: Any) -> None:
    if not fut.cancelled() and fut.exception() is not None:
        log.error("OPC UA: %s: %s", type(fut.exception()).__name__, fut.exception())


PUBLISHER = OpcUaServer
