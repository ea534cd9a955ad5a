"""The OPC UA server (asyncua): the appliance as a machine of OPC 40001-1 Machinery, its results after
OPC 40001-101 Machinery Result Transfer.

Address space (browse names; the namespace of each in brackets):

    Objects/Machines [Machinery]/<device id> [moi]
        Identification [DI]: Manufacturer, Model, SerialNumber, SoftwareRevision, ProductInstanceUri
        MachineryBuildingBlocks [DI]
            MachineryItemState [Machinery]/CurrentState: NotAvailable | OutOfService | NotExecuting | Executing
            MachineryOperationMode [Machinery]/CurrentState: Processing
            ResultManagement [Result]: GetLatestResult, GetResultById, AcknowledgeResults (methods);
                Results/LatestResult/ResultMetaData (ResultId, CreationTime, ProductId, PartId,
                ExternalRecipeId, ResultEvaluation), Results/LatestResult/ResultContent (J, J_U, J_u, U,
                omega_n, damping_ratio, flags); emits ResultReadyEventType [Result] per result.

The companion specifications' NodeSet2 files are not loaded (they are not shipped with the package): the
browse names are modelled in their namespaces with base types (folders, objects, properties), and a
result travels as the variables above, as a JSON document (methods, event field ``Result``) and in the
event's own fields. See docs/opcua.md.

The server runs on its own asyncio loop in a thread (``drivers.aioloop.LoopThread``); the daemon's hooks
hand it work and never wait for it.
"""

from __future__ import annotations

import asyncio
import hmac
import json
import logging
import math
import socket
import time
from collections import OrderedDict
from datetime import datetime, UTC
from pathlib import Path
from typing import Any, Mapping

from asyncua import Server, ua
from asyncua.crypto.cert_gen import setup_self_signed_certificate
from asyncua.crypto.permission_rules import User, UserRole
from asyncua.crypto.truststore import TrustStore
from asyncua.crypto.validator import CertificateValidator, CertificateValidatorOptions
from cryptography.x509.oid import ExtendedKeyUsageOID

from drivers.aioloop import LoopThread
from service.errors import ConfigError, OpcUaServerError
from service.publish.port import ApplianceView, Publisher

from .settings import OpcUaSettings

log = logging.getLogger("moi.opcua")

NS_MACHINERY = "http://opcfoundation.org/UA/Machinery/"
NS_RESULT = "http://opcfoundation.org/UA/Machinery/Result/"
NS_DI = "http://opcfoundation.org/UA/DI/"
NS_MOI = "urn:moi:opcua"

#: the appliance's state → MachineryItemState (OPC 40001-1)
ITEM_STATES: dict[str, str] = {
    "STARTING": "NotAvailable", "STOPPING": "NotAvailable", "FAULT": "OutOfService",
    "IDLE": "NotExecuting", "ABORTED": "NotExecuting",
    "ARMED": "Executing", "RELEASING": "Executing", "CAPTURING": "Executing", "IDENTIFYING": "Executing",
    "PUBLISHING": "Executing",
}

#: ResultEvaluationEnum of OPC 40001-101
RESULT_EVALUATION: dict[str, int] = {"Undefined": 0, "OK": 1, "NotOK": 2, "NotDecidable": 3}

#: the value of a variable before the first result (OPC UA has no null scalar of these types)
_EMPTY: dict[ua.VariantType, Any] = {ua.VariantType.String: "", ua.VariantType.Int32: 0,
                                     ua.VariantType.DateTime: datetime(1970, 1, 1, tzinfo=UTC)}

#: the method's wait for a result is limited to this, ms
MAX_TIMEOUT_MS = 60_000


def result_evaluation(payload: Mapping[str, Any]) -> str:
    """The verdict as ResultEvaluation: OK → OK, NOK → NotOK, INVALID or inside the guard band's uncertainty
    range → NotDecidable; no verdict (no recipe, part incomplete) → Undefined. The part's decision once the
    release completes it, else the release's."""
    decision = payload.get("part") or payload.get("release") or {}
    verdict = payload.get("verdict") or decision.get("verdict")
    if verdict == "INVALID" or (verdict is not None and decision.get("zone") == "uncertainty"):
        return "NotDecidable"
    return {"OK": "OK", "NOK": "NotOK"}.get(verdict or "", "Undefined")


def _num(v: Any) -> float | None:
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) else None


def result_document(payload: Mapping[str, Any]) -> dict[str, Any]:
    """A result as ResultMetaData and ResultContent (strict JSON: unknown numbers are null)."""
    recipe = payload.get("recipe") or {}
    decision = payload.get("part") or payload.get("release") or {}
    meta = {
        "ResultId": payload.get("uuid"),
        "CreationTime": payload.get("finished_at"),
        "ProductId": recipe.get("name"),
        "PartId": payload.get("part_id"),
        "ExternalRecipeId": recipe.get("name"),
        "ResultEvaluation": result_evaluation(payload),
        "SequenceNumber": payload.get("seq"),
    }
    content = {
        "J": _num(payload.get("J")),
        # the expanded uncertainty of J where the result carries it; J_u, the combined standard uncertainty
        # (fit ⊕ calibration ⊕ model form), always; U: the verdict's expanded uncertainty (with a recipe)
        "J_U": _num(payload.get("J_U")),
        "J_u": _num(payload.get("J_u")),
        "U": _num(decision.get("U")),
        "omega_n": _num(payload.get("omega_n")),
        "damping_ratio": _num(payload.get("damping_ratio")),
        "flags": list(payload.get("flags") or ()),
        "verdict": payload.get("verdict") or decision.get("verdict"),
    }
    return {"ResultMetaData": meta, "ResultContent": content}


class _Users:
    """asyncua's user manager: the one configured user (and anonymous clients when allowed)."""

    def __init__(self, username: str | None, password: str | None, anonymous: bool) -> None:
        self.username, self.password, self.anonymous = username, password, anonymous

    def get_user(self, iserver: Any, username: str | None = None, password: str | None = None,
                 certificate: Any = None) -> User | None:
        if username is None:
            return User(role=UserRole.User) if self.anonymous else None
        if self.username is None or self.password is None:
            return None
        ok = hmac.compare_digest(username.encode(), self.username.encode()) & hmac.compare_digest(
            (password or "").encode(), self.password.encode())
        return User(role=UserRole.User, name=username) if ok else None


class OpcUaServer(Publisher):
    """The OPC UA server; ``start()`` returns once it listens."""

    NAME = "opcua"

    def __init__(self, settings: OpcUaSettings, device_id: str, state_dir: Path, *, software_version: str = "",
                 store: Any = None) -> None:
        self.settings = settings
        self.device_id = device_id
        self.state_dir = Path(state_dir)
        self.software_version = software_version
        self.store = store
        self.password = self._password()
        self._io = LoopThread("moi-opcua")
        self._server: Server | None = None
        self.bound_port: int | None = None
        self.start_seconds: float | None = None  # how long the last start took, s
        self._results: OrderedDict[str, dict[str, Any]] = OrderedDict()  # uuid → document, newest last
        self._unacknowledged: OrderedDict[str, None] = OrderedDict()
        self._new_result: asyncio.Event | None = None
        self._nodes: dict[str, Any] = {}
        self._event: Any = None
        self._state = "STARTING"
        self.events_sent = 0

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
        cache = self._path(s.cache_file, "address-space")
        cert = self._path(s.certificate, "server-cert.der")
        key = self._path(s.private_key, "server-key.pem")
        for p in (cache, cert, key):
            p.parent.mkdir(mode=0o700, parents=True, exist_ok=True)  # the key is never readable by others
        server = Server(user_manager=_Users(s.username, self.password, s.anonymous))  # type: ignore[arg-type]
        await server.init(cache)
        server.set_endpoint(f"opc.tcp://{s.host}:{s.port}/moi/")
        server.set_server_name(f"moi {self.device_id}")
        uri = f"urn:moi:{self.device_id}"
        await server.set_application_uri(uri)
        await setup_self_signed_certificate(key, cert, uri, socket.gethostname(), [ExtendedKeyUsageOID.SERVER_AUTH],
                                            {"countryName": "DE", "organizationName": "moi",
                                             "commonName": f"moi {self.device_id}"})
        key.chmod(0o600)
        await server.load_certificate(str(cert))
        await server.load_private_key(str(key))
        policies = [ua.SecurityPolicyType.Basic256Sha256_SignAndEncrypt]
        if s.allow_unencrypted:
            policies.append(ua.SecurityPolicyType.NoSecurity)
        server.set_security_policy(policies)
        if s.trusted_clients is not None:
            trusted = Path(s.trusted_clients)
            if not trusted.is_dir():
                raise OpcUaServerError(f"[opcua] trusted_clients {s.trusted_clients!r} is not a directory")
            store = TrustStore([trusted], [])
            await store.load()
            server.set_certificate_validator(CertificateValidator(
                CertificateValidatorOptions.TRUSTED_VALIDATION | CertificateValidatorOptions.PEER_CLIENT, store))
        tokens: list[type] = [ua.UserNameIdentityToken]
        if s.anonymous:
            tokens.append(ua.AnonymousIdentityToken)
        server.set_identity_tokens(tokens)
        await self._build(server)
        self._new_result = asyncio.Event()
        await server.start()
        self._server = server
        bserver = server.bserver
        self.bound_port = getattr(bserver, "port", None) if bserver is not None else None

    async def _build(self, server: Server) -> None:
        s = self.settings
        idx = await server.register_namespace(NS_MOI)
        mach = await server.register_namespace(NS_MACHINERY)
        res = await server.register_namespace(NS_RESULT)
        di = await server.register_namespace(NS_DI)

        def nid(name: str) -> ua.NodeId:
            return ua.NodeId(ua.String(f"{self.device_id}.{name}"), ua.Int16(idx))

        machines = await server.nodes.objects.add_folder(ua.NodeId(ua.String("Machines"), ua.Int16(idx)),
                                                         ua.QualifiedName("Machines", mach))
        machine = await machines.add_object(nid("Machine"), ua.QualifiedName(self.device_id, idx))
        ident = await machine.add_object(nid("Identification"), ua.QualifiedName("Identification", di))
        for name, value in (("Manufacturer", ua.LocalizedText(s.manufacturer)), ("Model", ua.LocalizedText(s.model)),
                            ("SerialNumber", s.serial_number or self.device_id),
                            ("SoftwareRevision", self.software_version),
                            ("ProductInstanceUri", f"urn:moi:{s.manufacturer}:{s.serial_number or self.device_id}")):
            self._nodes[name] = await ident.add_property(nid(f"Identification.{name}"), ua.QualifiedName(name, di),
                                                         value)
        blocks = await machine.add_object(nid("MachineryBuildingBlocks"),
                                          ua.QualifiedName("MachineryBuildingBlocks", di))
        item = await blocks.add_object(nid("MachineryItemState"), ua.QualifiedName("MachineryItemState", mach))
        self._nodes["item_state"] = await item.add_variable(nid("MachineryItemState.CurrentState"),
                                                            ua.QualifiedName("CurrentState", 0),
                                                            ua.LocalizedText(ITEM_STATES["STARTING"]))
        mode = await blocks.add_object(nid("MachineryOperationMode"), ua.QualifiedName("MachineryOperationMode", mach))
        self._nodes["operation_mode"] = await mode.add_variable(nid("MachineryOperationMode.CurrentState"),
                                                                ua.QualifiedName("CurrentState", 0),
                                                                ua.LocalizedText("Processing"))
        rm = await blocks.add_object(nid("ResultManagement"), ua.QualifiedName("ResultManagement", res))
        self._nodes["result_management"] = rm
        results = await rm.add_folder(nid("Results"), ua.QualifiedName("Results", res))
        self._nodes["unacknowledged"] = await results.add_variable(
            nid("Results.UnacknowledgedCount"), ua.QualifiedName("UnacknowledgedCount", idx), 0, ua.VariantType.UInt32)
        latest = await results.add_object(nid("LatestResult"), ua.QualifiedName("LatestResult", res))
        meta = await latest.add_object(nid("LatestResult.ResultMetaData"), ua.QualifiedName("ResultMetaData", res))
        content = await latest.add_object(nid("LatestResult.ResultContent"), ua.QualifiedName("ResultContent", res))
        for name, vtype in (("ResultId", ua.VariantType.String), ("CreationTime", ua.VariantType.DateTime),
                            ("ProductId", ua.VariantType.String), ("PartId", ua.VariantType.String),
                            ("ExternalRecipeId", ua.VariantType.String), ("ResultEvaluation", ua.VariantType.Int32)):
            self._nodes[f"meta.{name}"] = await meta.add_variable(nid(f"LatestResult.{name}"),
                                                                  ua.QualifiedName(name, res), _EMPTY[vtype], vtype)
        for name, vtype in (("J", ua.VariantType.Double), ("J_U", ua.VariantType.Double),
                            ("J_u", ua.VariantType.Double), ("U", ua.VariantType.Double),
                            ("omega_n", ua.VariantType.Double), ("damping_ratio", ua.VariantType.Double)):
            self._nodes[f"content.{name}"] = await content.add_variable(nid(f"LatestResult.{name}"),
                                                                        ua.QualifiedName(name, idx), math.nan, vtype)
        self._nodes["content.flags"] = await content.add_variable(nid("LatestResult.flags"),
                                                                  ua.QualifiedName("flags", idx), [],
                                                                  ua.VariantType.String)
        self._nodes["content.json"] = await content.add_variable(nid("LatestResult.Document"),
                                                                 ua.QualifiedName("Document", idx), "", ua.VariantType.String)

        def arg(name: str, vtype: ua.VariantType, description: str, array: bool = False) -> ua.Argument:
            a = ua.Argument()
            a.Name = name
            a.DataType = ua.NodeId(ua.Int32(vtype.value))
            a.ValueRank = 1 if array else -1
            a.ArrayDimensions = [0] if array else []
            a.Description = ua.LocalizedText(description)
            return a

        result_arg = arg("Result", ua.VariantType.String, "the result: ResultMetaData and ResultContent as JSON")
        error_arg = arg("Error", ua.VariantType.Int32, "0: no error")
        await rm.add_method(nid("GetLatestResult"), ua.QualifiedName("GetLatestResult", res), self._get_latest,
                            [arg("Timeout", ua.VariantType.Int32, "wait at most this long for a result when none "
                                                                  "exists yet, ms (≤ 0: no wait)")],
                            [arg("ResultHandle", ua.VariantType.UInt32, "the result's sequence number"),
                             result_arg, error_arg])
        await rm.add_method(nid("GetResultById"), ua.QualifiedName("GetResultById", res), self._get_by_id,
                            [arg("ResultId", ua.VariantType.String, "the result's UUID"),
                             arg("Timeout", ua.VariantType.Int32, "ignored: a stored result is there at once, ms")],
                            [result_arg, error_arg])
        await rm.add_method(nid("AcknowledgeResults"), ua.QualifiedName("AcknowledgeResults", res), self._acknowledge,
                            [arg("ResultIds", ua.VariantType.String, "the UUIDs of the results acknowledged", True)],
                            [error_arg])
        etype = await server.create_custom_event_type(
            res, "ResultReadyEventType", ua.ObjectIds.BaseEventType,
            [("ResultId", ua.VariantType.String), ("ResultEvaluation", ua.VariantType.Int32),
             ("PartId", ua.VariantType.String), ("ExternalRecipeId", ua.VariantType.String),
             ("Result", ua.VariantType.String)])
        self._event = await server.get_event_generator(etype, rm.nodeid)

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

    def failure(self) -> str | None:
        return None if self._io.running else "the OPC UA server thread stopped"

    def where(self) -> str:
        return f"OPC UA {self.endpoint}"

    def health(self) -> dict[str, Any]:
        return {"endpoint": self.endpoint, "results_unacknowledged": len(self._unacknowledged),
                "events_sent": self.events_sent, "start_seconds": self.start_seconds}

    # --- methods (the server's loop) --------------------------------------------------------------
    @staticmethod
    def _int32(v: Any) -> int | None:
        value = getattr(v, "Value", v)
        return value if isinstance(value, int) and not isinstance(value, bool) else None

    async def _get_latest(self, parent: ua.NodeId, *args: Any) -> Any:
        if len(args) != 1 or (timeout := self._int32(args[0])) is None:
            return _bad(ua.StatusCodes.BadInvalidArgument)
        if not self._results and timeout > 0 and self._new_result is not None:
            try:
                await asyncio.wait_for(self._new_result.wait(), min(timeout, MAX_TIMEOUT_MS) / 1000)
            except TimeoutError:
                pass
        if not self._results:
            if self.store is not None:
                last = await asyncio.to_thread(self.store.latest, "ok")
                if last is not None and last.payload is not None:
                    return self._outputs(result_document(last.payload), handle=True)
            return _bad(ua.StatusCodes.BadNoData)
        return self._outputs(next(reversed(self._results.values())), handle=True)

    async def _get_by_id(self, parent: ua.NodeId, *args: Any) -> Any:
        result_id = getattr(args[0], "Value", None) if args else None
        if len(args) not in (1, 2) or not isinstance(result_id, str) or not result_id:
            return _bad(ua.StatusCodes.BadInvalidArgument)
        doc = self._results.get(result_id)
        if doc is None and self.store is not None and len(result_id) == 36:
            stored = await asyncio.to_thread(self.store.get, result_id)
            if stored is not None and stored.uuid == result_id and stored.payload is not None:
                doc = result_document(stored.payload)
        if doc is None:
            return _bad(ua.StatusCodes.BadNotFound)
        return self._outputs(doc, handle=False)

    async def _acknowledge(self, parent: ua.NodeId, *args: Any) -> Any:
        ids = getattr(args[0], "Value", None) if len(args) == 1 else None
        if not isinstance(ids, list) or not ids or not all(isinstance(i, str) for i in ids):
            return _bad(ua.StatusCodes.BadInvalidArgument)
        if any(i not in self._unacknowledged for i in ids):
            return _bad(ua.StatusCodes.BadNotFound)  # none is acknowledged
        for i in ids:
            del self._unacknowledged[i]
        await self._nodes["unacknowledged"].write_value(ua.Variant(len(self._unacknowledged), ua.VariantType.UInt32))
        return [ua.Variant(0, ua.VariantType.Int32)]

    @staticmethod
    def _outputs(doc: Mapping[str, Any], handle: bool) -> list[ua.Variant]:
        out = [ua.Variant(json.dumps(doc, allow_nan=False), ua.VariantType.String), ua.Variant(0, ua.VariantType.Int32)]
        if handle:
            seq = doc["ResultMetaData"].get("SequenceNumber") or 0
            out.insert(0, ua.Variant(int(seq) & 0xFFFFFFFF, ua.VariantType.UInt32))
        return out

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
            self._submit(self._write_state(ITEM_STATES.get(state, "NotAvailable")))

    async def _write_state(self, text: str) -> None:
        await self._nodes["item_state"].write_value(ua.LocalizedText(text))

    def on_result(self, stored: Any, measurement: Any) -> None:
        if stored.payload is not None:
            self.publish_result(stored.payload)

    def publish_result(self, payload: Mapping[str, Any]) -> None:
        """A stored result: the LatestResult variables, the list the methods read and a ResultReadyEvent."""
        self._submit(self._publish(result_document(payload)))

    async def _publish(self, doc: dict[str, Any]) -> None:
        meta, content = doc["ResultMetaData"], doc["ResultContent"]
        rid = str(meta["ResultId"])
        self._results[rid] = doc
        while len(self._results) > max(1, self.settings.results_kept):
            self._results.popitem(last=False)
        self._unacknowledged[rid] = None
        while len(self._unacknowledged) > max(1, self.settings.results_kept):
            self._unacknowledged.popitem(last=False)
        created = meta["CreationTime"]
        values: dict[str, ua.Variant] = {
            "meta.ResultId": ua.Variant(rid, ua.VariantType.String),
            "meta.CreationTime": ua.Variant(datetime.fromisoformat(created.replace("Z", "+00:00")) if isinstance(
                created, str) else _EMPTY[ua.VariantType.DateTime], ua.VariantType.DateTime),
            "meta.ProductId": ua.Variant(meta["ProductId"] or "", ua.VariantType.String),
            "meta.PartId": ua.Variant(meta["PartId"] or "", ua.VariantType.String),
            "meta.ExternalRecipeId": ua.Variant(meta["ExternalRecipeId"] or "", ua.VariantType.String),
            "meta.ResultEvaluation": ua.Variant(RESULT_EVALUATION[meta["ResultEvaluation"]], ua.VariantType.Int32),
            "content.flags": ua.Variant(content["flags"], ua.VariantType.String),
            "content.json": ua.Variant(json.dumps(doc, allow_nan=False), ua.VariantType.String),
        }
        for name in ("J", "J_U", "J_u", "U", "omega_n", "damping_ratio"):
            v = content[name]
            values[f"content.{name}"] = ua.Variant(math.nan if v is None else v, ua.VariantType.Double)
        for key, variant in values.items():
            await self._nodes[key].write_value(variant)
        await self._nodes["unacknowledged"].write_value(ua.Variant(len(self._unacknowledged), ua.VariantType.UInt32))
        ev = self._event
        ev.event.ResultId = rid
        ev.event.ResultEvaluation = RESULT_EVALUATION[meta["ResultEvaluation"]]
        ev.event.PartId = meta["PartId"] or ""
        ev.event.ExternalRecipeId = meta["ExternalRecipeId"] or ""
        ev.event.Result = json.dumps(doc, allow_nan=False)
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
                     store=appliance.store)
        return server


def _bad(code: int) -> ua.StatusCode:
    """A method's Bad status code (the client's call raises it)."""
    return ua.StatusCode(ua.UInt32(code))


def _log_failure(fut: Any) -> None:
    if not fut.cancelled() and fut.exception() is not None:
        log.error("OPC UA: %s: %s", type(fut.exception()).__name__, fut.exception())


PUBLISHER = OpcUaServer
