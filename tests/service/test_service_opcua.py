"""The OPC UA server of the daemon against asyncua's own client on loopback (Basic256Sha256 Sign & Encrypt,
user and password): browse the Machinery building blocks, receive the ResultReadyEvent of a measurement,
read the latest result, call the Result Transfer methods, and be refused without the right credentials.
One appliance (and one server) for the module: an encrypted session costs RSA work."""

from __future__ import annotations

import asyncio
import json
from pathlib import Path

import pytest
from asyncua import Client, ua
from asyncua.crypto.cert_gen import setup_self_signed_certificate
from asyncua.crypto.security_policies import SecurityPolicyBasic256Sha256
from cryptography.x509.oid import ExtendedKeyUsageOID

from service.publish.opcua.server import NS_DI, NS_MACHINERY, NS_MOI, NS_RESULT, RESULT_EVALUATION

from .conftest import RunningAppliance, appliance_doc

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


async def machine(c: Client):
    ns = {u: await c.get_namespace_index(u) for u in (NS_MACHINERY, NS_MOI, NS_DI, NS_RESULT)}
    m = await c.nodes.objects.get_child([f"{ns[NS_MACHINERY]}:Machines", f"{ns[NS_MOI]}:test-rig"])
    return m, ns


def test_browse_machine_identification_and_item_state(opc):
    async def run():
        c = await connect(opc)
        try:
            m, ns = await machine(c)
            ident = await m.get_child(f"{ns[NS_DI]}:Identification")
            values = {(await n.read_browse_name()).Name: await n.read_value() for n in await ident.get_children()}
            assert values["SerialNumber"] == "SN-0007" and values["Manufacturer"].Text == "moi"
            assert set(values) == {"Manufacturer", "Model", "SerialNumber", "SoftwareRevision", "ProductInstanceUri"}
            state = await m.get_child([f"{ns[NS_DI]}:MachineryBuildingBlocks", f"{ns[NS_MACHINERY]}:MachineryItemState",
                                       "0:CurrentState"])
            assert (await state.read_value()).Text == "NotExecuting"
            mode = await m.get_child([f"{ns[NS_DI]}:MachineryBuildingBlocks",
                                      f"{ns[NS_MACHINERY]}:MachineryOperationMode", "0:CurrentState"])
            assert (await mode.read_value()).Text == "Processing"
            with pytest.raises(ua.UaStatusCodeError):  # read-only: a client changes nothing
                await state.write_value(ua.LocalizedText("Executing"))
            assert (await state.read_value()).Text == "NotExecuting"
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


def test_a_measurement_raises_result_ready_and_the_methods_give_and_acknowledge_it(opc):
    app = opc[0]

    async def run():
        c = await connect(opc)
        try:
            m, ns = await machine(c)
            r = ns[NS_RESULT]
            rm = await m.get_child([f"{ns[NS_DI]}:MachineryBuildingBlocks", f"{r}:ResultManagement"])
            etype = await c.nodes.base_event_type.get_child(f"{r}:ResultReadyEventType")
            events = _Events()
            sub = await c.create_subscription(50, events)
            await sub.subscribe_events(rm, etype)
            item_state = await m.get_child([f"{ns[NS_DI]}:MachineryBuildingBlocks",
                                            f"{ns[NS_MACHINERY]}:MachineryItemState", "0:CurrentState"])
            await sub.subscribe_data_change(item_state)
            app.press()
            await asyncio.wait_for(events.arrived.wait(), 60)
            ev = events.got[0]
            uuid = app.app.stored[0]
            await asyncio.wait_for(events.executing.wait(), 10)  # the machine was measuring before the result
            assert ev.ResultId == uuid and ev.ResultEvaluation == RESULT_EVALUATION["Undefined"]  # no recipe
            doc = json.loads(ev.Result)
            assert doc["ResultContent"]["J"] == pytest.approx(app.app.store.get(uuid).payload["J"])

            latest = await rm.get_child([f"{r}:Results", f"{r}:LatestResult", f"{r}:ResultMetaData", f"{r}:ResultId"])
            assert await latest.read_value() == uuid
            handle, text, error = await rm.call_method(f"{r}:GetLatestResult", ua.Variant(0, ua.VariantType.Int32))
            assert error == 0 and json.loads(text)["ResultMetaData"]["ResultId"] == uuid and handle >= 1
            text, error = await rm.call_method(f"{r}:GetResultById", uuid, ua.Variant(0, ua.VariantType.Int32))
            assert json.loads(text)["ResultMetaData"]["ResultId"] == uuid

            # bad input: a Bad status code, and nothing changes
            with pytest.raises(ua.UaStatusCodeError) as e:
                await rm.call_method(f"{r}:GetResultById", "no-such-result", ua.Variant(0, ua.VariantType.Int32))
            assert e.value.code == ua.StatusCodes.BadNotFound
            with pytest.raises(ua.UaStatusCodeError) as e:
                await rm.call_method(f"{r}:AcknowledgeResults", ua.Variant(["no-such-result", uuid], ua.VariantType.String))
            assert e.value.code == ua.StatusCodes.BadNotFound
            with pytest.raises(ua.UaStatusCodeError) as e:
                await rm.call_method(f"{r}:GetLatestResult", "soon")
            assert e.value.code == ua.StatusCodes.BadInvalidArgument
            count = await rm.get_child([f"{r}:Results", f"{ns[NS_MOI]}:UnacknowledgedCount"])
            assert await count.read_value() == 1

            assert await rm.call_method(f"{r}:AcknowledgeResults", ua.Variant([uuid], ua.VariantType.String)) == 0
            assert await count.read_value() == 0
            with pytest.raises(ua.UaStatusCodeError):  # acknowledged once: not again
                await rm.call_method(f"{r}:AcknowledgeResults", ua.Variant([uuid], ua.VariantType.String))
            await sub.delete()
        finally:
            await c.disconnect()

    asyncio.run(run())
    app.wait_done(1)


@pytest.mark.parametrize("user, password", [(None, None), (USER, "wrong"), ("nobody", PASSWORD)])
def test_anonymous_and_wrong_credentials_are_refused(opc, user, password):
    async def run():
        with pytest.raises(ua.UaStatusCodeError) as e:
            c = await connect(opc, user, password)
            await c.disconnect()
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
    from service.publish.opcua.server import ITEM_STATES, result_evaluation
    from service.states import STATES

    assert set(ITEM_STATES) == set(STATES)
    assert set(ITEM_STATES.values()) == {"NotAvailable", "OutOfService", "NotExecuting", "Executing"}
    assert result_evaluation({"verdict": "OK", "part": {"verdict": "OK", "zone": "conformance"}}) == "OK"
    assert result_evaluation({"verdict": "NOK", "part": {"verdict": "NOK", "zone": "nonconformance"}}) == "NotOK"
    assert result_evaluation({"verdict": "NOK", "part": {"verdict": "NOK", "zone": "uncertainty"}}) == "NotDecidable"
    assert result_evaluation({"verdict": "INVALID", "part": {"verdict": "INVALID"}}) == "NotDecidable"
    assert result_evaluation({"verdict": None, "release": {"verdict": "OK", "zone": "conformance"}}) == "OK"
    assert result_evaluation({}) == "Undefined"


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
            await c.disconnect()
        assert e.value.code == ua.StatusCodes.BadCertificateUntrusted

    asyncio.run(run())
