"""The OPC UA server of the daemon against asyncua's own client on loopback (Basic256Sha256 Sign & Encrypt,
user and password): browse the Machinery building blocks and check their type definitions, receive the
ResultReadyEvent of a measurement, read the latest result as a ResultDataType, call the Result Transfer
methods, keep the acknowledgements across a restart, and be refused without the right credentials.
One appliance (and one server) for the module: an encrypted session costs RSA work."""

from __future__ import annotations

import asyncio
import json
import re
import subprocess
import sys
import textwrap
from pathlib import Path
from types import SimpleNamespace

import pytest
from asyncua import Client, ua
from asyncua.crypto.cert_gen import setup_self_signed_certificate
from asyncua.crypto.security_policies import SecurityPolicyBasic256Sha256
from cryptography.x509.oid import ExtendedKeyUsageOID

from service.publish.opcua.model import NS_DI, NS_MACHINERY, NS_MOI, NS_RESULT, RESULT_EVALUATION
from tests.service.conftest import REPO, RunningAppliance, appliance_doc

USER, PASSWORD = "line-7", "s3cret"


@pytest.fixture(scope="module")
def opc(tmp_path_factory):
    base = tmp_path_factory.mktemp("opcua")
    pw = base / "opcua-password"
    pw.write_text(PASSWORD + "\n", encoding="utf-8")
    trusted = base / "trusted"
    trusted.mkdir()
    key, cert = base / "client-key.pem", trusted / "client-cert.der"
    asyncio.run(setup_self_signed_certificate(key, cert, "urn:moi-test:client", "localhost",
                                              [ExtendedKeyUsageOID.CLIENT_AUTH], {"commonName": "moi test client"}))
    doc = appliance_doc(base / "state", opcua={"host": "127.0.0.1", "port": 0, "username": USER,
                                               "password_file": str(pw), "serial_number": "SN-0007",
                                               "trusted_clients": str(trusted)})
    app = RunningAppliance(doc)
    try:
        yield app, key, cert
    finally:
        app.stop()


async def connect(opc, user: str | None = USER, password: str | None = PASSWORD) -> Client:
    app, key, cert = opc
    c = Client(app.app.opcua.endpoint, timeout=10)
    c.application_uri = "urn:moi-test:client"
    await c.set_security(SecurityPolicyBasic256Sha256, str(cert), str(key), mode=ua.MessageSecurityMode.SignAndEncrypt)
    if user is not None:
        c.set_user(user)
        c.set_password(password or "")
    await c.connect()
    return c


async def machine(c: Client, device: str = "test-rig"):
    ns = {u: await c.get_namespace_index(u) for u in (NS_MACHINERY, NS_MOI, NS_DI, NS_RESULT)}
    m = await c.nodes.objects.get_child([f"{ns[NS_MACHINERY]}:Machines", f"{ns[NS_MOI]}:{device}"])
    return m, ns


async def result_management(c: Client, device: str = "test-rig"):
    m, ns = await machine(c, device)
    r = ns[NS_RESULT]
    return await m.get_child([f"{ns[NS_MACHINERY]}:MachineryBuildingBlocks", f"{r}:ResultManagement"]), r, ns


class _Changes:
    """Data changes of the subscribed CurrentState variables, and an event once a wanted value arrives."""

    def __init__(self) -> None:
        self.values: list[str] = []
        self.wanted: tuple[str, asyncio.Event] | None = None

    def want(self, text: str) -> asyncio.Event:
        self.wanted = (text, asyncio.Event())
        if text in self.values[-2:]:
            self.wanted[1].set()
        return self.wanted[1]

    def datachange_notification(self, node, value, data) -> None:
        self.values.append(value.Text)
        if self.wanted is not None and value.Text == self.wanted[0]:
            self.wanted[1].set()


def test_the_machine_browses_as_the_companion_specifications_types(opc):
    app = opc[0]

    async def run():
        c = await connect(opc)
        try:
            m, ns = await machine(c)
            mach, r, di = ns[NS_MACHINERY], ns[NS_RESULT], ns[NS_DI]
            ident = await m.get_child(f"{di}:Identification")
            assert await ident.read_type_definition() == ua.NodeId(ua.Int32(1012), mach)  # MachineIdentificationType
            values = {(await n.read_browse_name()).Name: await n.read_value() for n in await ident.get_children()}
            assert values["SerialNumber"] == "SN-0007" and values["Manufacturer"].Text == "moi"
            assert {"Manufacturer", "Model", "SerialNumber", "SoftwareRevision", "ProductInstanceUri"} <= set(values)
            blocks = await m.get_child(f"{mach}:MachineryBuildingBlocks")
            typed = {(await n.read_browse_name()).Name: await n.read_type_definition()
                     for n in await blocks.get_children(refs=ua.ObjectIds.HasAddIn)}
            assert typed == {"Identification": ua.NodeId(ua.Int32(1012), mach),
                             "MachineryItemState": ua.NodeId(ua.Int32(1002), mach),  # MachineryItemState_StateMachineType
                             "MachineryOperationMode": ua.NodeId(ua.Int32(1008), mach),  # ...OperationModeStateMachineType
                             "ResultManagement": ua.NodeId(ua.Int32(1004), r)}  # ResultManagementType
            state = await blocks.get_child([f"{mach}:MachineryItemState", "0:CurrentState"])
            assert (await state.read_value()).Text == "NotExecuting"
            assert await (await state.get_child("0:Id")).read_value() == ua.NodeId(ua.Int32(5007), mach)  # the state object
            latest = await blocks.get_child([f"{r}:ResultManagement", f"{r}:Results", f"{r}:LatestResult"])
            assert await latest.read_type_definition() == ua.NodeId(ua.Int32(2001), r)  # ResultType
            assert await latest.read_data_type() == ua.NodeId(ua.Int32(3008), r)  # ResultDataType
            with pytest.raises(ua.UaStatusCodeError):  # read-only: a client changes nothing
                await state.write_value(ua.LocalizedText("Executing"))
            assert (await state.read_value()).Text == "NotExecuting"

            # MachineryOperationMode follows the appliance: a check standard recipe is Maintenance
            mode = await blocks.get_child([f"{mach}:MachineryOperationMode", "0:CurrentState"])
            changes = _Changes()
            sub = await c.create_subscription(20, changes)
            await sub.subscribe_data_change(mode)
            await asyncio.wait_for(changes.want("Processing").wait(), 10)
            arrived = changes.want("Maintenance")
            app.app.opcua.on_recipe(SimpleNamespace(check_standard={"name": "ring"}))
            await asyncio.wait_for(arrived.wait(), 10)
            assert await (await mode.get_child("0:Id")).read_value() == ua.NodeId(ua.Int32(5025), mach)
            arrived = changes.want("Processing")
            app.app.opcua.on_recipe(None)
            await asyncio.wait_for(arrived.wait(), 10)
            await sub.delete()
        finally:
            await c.disconnect()

    asyncio.run(run())


class _Events:
    def __init__(self) -> None:
        self.got: list = []
        self.states: list[str] = []  # MachineryItemState as it changed
        self.executing = asyncio.Event()
        self.arrived = asyncio.Event()

    def event_notification(self, event) -> None:
        self.got.append(event)
        self.arrived.set()

    def datachange_notification(self, node, value, data) -> None:
        self.states.append(value.Text)
        if value.Text == "Executing":
            self.executing.set()


def _acknowledge(ids: list[str]) -> ua.Variant:
    return ua.Variant(ids, ua.VariantType.String)


def test_a_measurement_raises_result_ready_and_the_methods_give_and_acknowledge_it(opc):
    app = opc[0]

    async def run():
        c = await connect(opc)
        try:
            await c.load_data_type_definitions()
            rm, r, ns = await result_management(c)
            etype = await c.nodes.base_event_type.get_child(f"{r}:ResultReadyEventType")
            events = _Events()
            sub = await c.create_subscription(50, events)
            await sub.subscribe_events(rm, etype)
            m, _ = await machine(c)
            item_state = await m.get_child([f"{ns[NS_MACHINERY]}:MachineryBuildingBlocks",
                                            f"{ns[NS_MACHINERY]}:MachineryItemState", "0:CurrentState"])
            await sub.subscribe_data_change(item_state)
            app.press()
            await asyncio.wait_for(events.arrived.wait(), 60)
            ev = events.got[0]
            uuid = app.app.stored[0]
            stored = app.app.store.get(uuid)
            await asyncio.wait_for(events.executing.wait(), 10)  # the machine was measuring before the result
            meta, content = ev.Result.ResultMetaData, ev.Result.ResultContent[0].Value
            assert type(ev.Result).__name__ == "ResultDataType" and meta.ResultId == uuid
            assert meta.ResultEvaluation == RESULT_EVALUATION["Undefined"]  # no recipe
            assert meta.ResultState == 1 and meta.IsSimulated is True and meta.ProcessingTimes is not None
            assert type(content).__name__ == "InertiaResultDataType" and content.SequenceNumber == stored.seq
            assert pytest.approx(stored.payload["J"]) == content.J
            assert content.omega_n == pytest.approx(stored.payload["omega_n"])

            latest = await rm.get_child([f"{r}:Results", f"{r}:LatestResult"])
            assert (await latest.read_value()).ResultMetaData.ResultId == uuid
            rid = await latest.get_child([f"{r}:ResultMetaData", f"{r}:ResultId"])
            assert await rid.read_value() == uuid
            handle, result, error = await rm.call_method(f"{r}:GetLatestResult", ua.Variant(0, ua.VariantType.Int32))
            assert (handle, error) == (0, 0) and result.ResultMetaData.ResultId == uuid
            handle, result, error = await rm.call_method(f"{r}:GetResultById", uuid,
                                                         ua.Variant(0, ua.VariantType.Int32))
            assert error == 0 and pytest.approx(stored.payload["J"]) == result.ResultContent[0].Value.J

            # bad input: a Bad status code, and nothing changes
            with pytest.raises(ua.UaStatusCodeError) as e:
                await rm.call_method(f"{r}:GetResultById", "no-such-result", ua.Variant(0, ua.VariantType.Int32))
            assert e.value.code == ua.StatusCodes.BadNotFound
            for method, args in (("GetLatestResult", ["soon"]), ("AcknowledgeResults", [_acknowledge([])]),
                                 ("AcknowledgeResults", [ua.Variant(7, ua.VariantType.Int32)]),
                                 ("GetResultById", [uuid, "soon"])):
                with pytest.raises(ua.UaStatusCodeError) as e:
                    await rm.call_method(f"{r}:{method}", *args)
                assert e.value.code == ua.StatusCodes.BadInvalidArgument
            count = await rm.get_child([f"{r}:Results", f"{ns[NS_MOI]}:UnacknowledgedCount"])
            assert await count.read_value() == 1
            # an unknown ResultId: its own error, the call's error, nothing acknowledged
            assert await rm.call_method(f"{r}:AcknowledgeResults", _acknowledge(["no-such-result"])) == [[-1], -1]
            assert await count.read_value() == 1

            assert await rm.call_method(f"{r}:AcknowledgeResults", _acknowledge([uuid])) == [[], 0]
            assert await count.read_value() == 0
            # acknowledged once: not again
            assert await rm.call_method(f"{r}:AcknowledgeResults", _acknowledge([uuid])) == [[-2], -1]
            await sub.delete()
        finally:
            await c.disconnect()

    asyncio.run(run())
    app.wait_done(1)


#: an asyncua client in a process of its own: its classes made from the server's DataTypeDefinitions (in this
#: process they are the server's), then the class docs/opcua.md gives asyncua 2.1 clients (SNIPPET)
_OWN_CLIENT = """
import asyncio, json, sys
from asyncua import Client, ua as _ua  # the snippet imports ua itself
from asyncua.crypto.security_policies import SecurityPolicyBasic256Sha256

async def main(endpoint, cert, key, user, password):
    client = Client(endpoint, timeout=10)
    client.application_uri = "urn:moi-test:client"
    await client.set_security(SecurityPolicyBasic256Sha256, cert, key, mode=_ua.MessageSecurityMode.SignAndEncrypt)
    client.set_user(user)
    client.set_password(password)
    async with client:
        await client.load_data_type_definitions()
SNIPPET
        moi = await client.get_namespace_index("urn:moi:opcua")
        value = await client.get_node(ua.NodeId("test-rig.Results.LatestResult", moi)).read_value()
        content = value.ResultContent[0].Value
        print(json.dumps({"class": type(value).__name__, "ResultId": value.ResultMetaData.ResultId,
                          "meta": type(value.ResultMetaData).__name__, "J": content.J}))

asyncio.run(main(*sys.argv[1:]))
"""


def test_an_asyncua_client_of_its_own_decodes_the_result_with_the_documented_class(opc):
    app, key, cert = opc
    if not app.app.stored:  # alone: the module's measurement has not run
        app.press()
        app.wait_done(1)
    doc = (REPO / "docs" / "opcua.md").read_text(encoding="utf-8")
    snippet = re.search(r"asyncua 2.1 as a client.*?```python\n(.*?)```", doc, flags=re.S)
    assert snippet is not None, "docs/opcua.md gives asyncua clients no class"
    script = _OWN_CLIENT.replace("SNIPPET", textwrap.indent(snippet.group(1), " " * 8))
    run = subprocess.run([sys.executable, "-c", script, app.app.opcua.endpoint, str(cert), str(key), USER, PASSWORD],
                         capture_output=True, text=True, timeout=120, check=False)
    assert run.returncode == 0, run.stderr[-2000:]
    got = json.loads(run.stdout.splitlines()[-1])
    stored = app.app.store.get(app.app.stored[-1])
    assert got == {"class": "ResultDataType", "ResultId": stored.uuid, "meta": "ResultMetaDataType",
                   "J": pytest.approx(stored.payload["J"], rel=1e-12)}


@pytest.mark.parametrize(("user", "password"), [(None, None), (USER, "wrong"), ("nobody", PASSWORD)])
def test_anonymous_and_wrong_credentials_are_refused(opc, user, password):
    async def run():
        with pytest.raises(ua.UaStatusCodeError) as e:
            await connect(opc, user, password)
        assert e.value.code in (ua.StatusCodes.BadUserAccessDenied, ua.StatusCodes.BadIdentityTokenRejected,
                                ua.StatusCodes.BadIdentityTokenInvalid)

    asyncio.run(run())


def test_no_unencrypted_endpoint_is_offered_and_the_certificate_was_made(opc):
    app = opc[0]

    async def run():
        c = Client(app.app.opcua.endpoint, timeout=10)
        endpoints = await c.connect_and_get_server_endpoints()
        assert endpoints and all(e.SecurityMode == ua.MessageSecurityMode.SignAndEncrypt for e in endpoints)
        assert {e.SecurityPolicyUri for e in endpoints} == {SecurityPolicyBasic256Sha256.URI}

    asyncio.run(run())
    state = Path(app.config.state_dir) / "opcua"
    assert (state / "server-cert.der").stat().st_size > 0 and (state / "server-key.pem").stat().st_mode & 0o077 == 0


def test_every_appliance_state_has_a_machinery_item_state_and_every_verdict_an_evaluation():
    from service.parts.outcome import PartOutcome
    from service.publish.opcua.server import ITEM_STATES, result_evaluation
    from service.states import STATES

    def evaluation(payload):
        return result_evaluation(PartOutcome.from_dict(payload))

    assert set(ITEM_STATES) == set(STATES)
    assert set(ITEM_STATES.values()) == {"NotAvailable", "OutOfService", "NotExecuting", "Executing"}
    assert evaluation({"verdict": "OK", "part": {"verdict": "OK", "zone": "conformance"}}) == "OK"
    assert evaluation({"verdict": "NOK", "part": {"verdict": "NOK", "zone": "nonconformance"}}) == "NotOK"
    assert evaluation({"verdict": "NOK", "part": {"verdict": "NOK", "zone": "uncertainty"}}) == "NotDecidable"
    assert evaluation({"verdict": "INVALID", "part": {"verdict": "INVALID"}}) == "NotDecidable"
    assert evaluation({"verdict": None, "release": {"verdict": "OK", "zone": "conformance"}}) == "OK"
    assert evaluation({}) == "Undefined"


def test_the_operation_mode_follows_the_appliance():
    from service.publish.opcua.model import OPERATION_MODE_NODES
    from service.publish.opcua.server import operation_mode
    from service.states import STATES

    modes = {operation_mode(s, c, d) for s in STATES for c in (False, True) for d in (False, True)}
    assert modes == set(OPERATION_MODE_NODES)  # None, Maintenance, Setup, Processing: each one reached
    assert operation_mode("STARTING", True, True) == "None"
    assert operation_mode("IDLE", True, True) == "Maintenance"  # a check standard clears what is due
    assert operation_mode("CAPTURING", False, True) == "Setup"
    assert operation_mode("FAULT", False, False) == "Processing"  # the fault is the item state's


def test_opcua_is_off_by_default_and_a_table_without_a_way_in_is_refused_with_one_line(tmp_path):
    from service.config.appliance import parse_config
    from service.errors import ConfigError

    doc = appliance_doc(tmp_path / "state")
    assert parse_config(doc, source="t.toml").opcua is None
    for table, words in (({}, "no client could log in"), ({"username": "u"}, "needs a password"),
                         ({"username": "u", "password": "p", "password_file": "f"}, "not both")):
        with pytest.raises(ConfigError, match=words):
            parse_config(appliance_doc(tmp_path / "state", opcua=table), source="t.toml")
    s = parse_config(appliance_doc(tmp_path / "state", opcua={"anonymous": True}), source="t.toml").opcua
    assert s is not None and s.host == "127.0.0.1" and s.anonymous and not s.allow_unencrypted


def test_a_client_certificate_outside_trusted_clients_is_refused(opc, tmp_path):
    app, _, _ = opc
    key, cert = tmp_path / "stranger-key.pem", tmp_path / "stranger-cert.der"

    async def run():
        await setup_self_signed_certificate(key, cert, "urn:moi-test:stranger", "localhost",
                                            [ExtendedKeyUsageOID.CLIENT_AUTH], {"commonName": "stranger"})
        c = Client(app.app.opcua.endpoint, timeout=10)
        c.application_uri = "urn:moi-test:stranger"
        await c.set_security(SecurityPolicyBasic256Sha256, str(cert), str(key),
                             mode=ua.MessageSecurityMode.SignAndEncrypt)
        c.set_user(USER)
        c.set_password(PASSWORD)  # the right password does not admit an untrusted application
        with pytest.raises(ua.UaStatusCodeError) as e:
            await c.connect()
        assert e.value.code == ua.StatusCodes.BadCertificateUntrusted

    asyncio.run(run())


def test_the_acknowledgements_survive_a_restart(opc):
    """After the module's first result was acknowledged, a second one is not: an OPC UA server started anew on
    the same state directory and store (a restart) offers the second again, and knows the first as
    acknowledged. Last in the module: the new server writes the acknowledgements the daemon's server keeps."""
    from service.persistence.acks import AckFile
    from service.publish.opcua.server import ACKED_FILE, OpcUaServer
    from service.publish.opcua.settings import OpcUaSettings

    app = opc[0]
    first = app.app.stored[0]
    app.press()
    app.wait_done(2)
    second = app.app.stored[1]
    state_dir = Path(app.config.state_dir)
    restarted = OpcUaServer(OpcUaSettings(port=0, anonymous=True, allow_unencrypted=True), "test-rig", state_dir,
                            store=app.app.store)
    restarted.start()

    async def run():
        async with Client(restarted.endpoint, timeout=10) as c:
            rm, r, ns = await result_management(c)
            count = await rm.get_child([f"{r}:Results", f"{ns[NS_MOI]}:UnacknowledgedCount"])
            assert await count.read_value() == 1
            latest = await rm.get_child([f"{r}:Results", f"{r}:LatestResult", f"{r}:ResultMetaData", f"{r}:ResultId"])
            assert await latest.read_value() == second  # LatestResult from the store before any new result
            assert await rm.call_method(f"{r}:AcknowledgeResults", _acknowledge([first, second])) == [[-2, 0], -1]
            assert await count.read_value() == 0

    try:
        asyncio.run(run())
    finally:
        restarted.stop()
    kept = AckFile(state_dir / ACKED_FILE).read()
    assert kept is not None and kept.through == app.app.store.get(second).seq and not kept.pending


def test_the_acknowledgement_file_reads_what_it_wrote_and_the_modbus_position_of_old(tmp_path):
    from service.persistence.acks import AckFile, AckState

    f = AckFile(tmp_path / "acked")
    assert f.read() is None  # none kept: the reader's first start
    f.write(AckState(41, frozenset({7, 40})))
    kept = f.read()
    assert kept == AckState(41, frozenset({7, 40})) and kept.acknowledged(41) and not kept.acknowledged(40)
    assert not kept.acknowledged(42)
    (tmp_path / "acked").write_text("12\n", encoding="ascii")  # the Modbus FIFO's file: the position alone
    assert f.read() == AckState(12)
    (tmp_path / "acked").write_text("garbage\n", encoding="ascii")
    assert f.read() == AckState(0)  # damaged: nothing acknowledged (quarantined)
