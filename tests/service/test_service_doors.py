"""The doors added since the last attack pass (OPC UA, MQTT replies, hostile names) must not let anyone stop a
measurement or lose one: attacks on the running daemon (simulated rig, loopback only, bounded in count)."""

from __future__ import annotations

import json
import socket
from pathlib import Path

import pytest

from tests.service.conftest import appliance_doc, login_from, wait_until

# --- a measurement once captured is always stored ---------------------------------------------------------------

def test_a_failure_while_the_part_is_judged_still_stores_the_measurement_with_its_trace(tmp_path, appliance_factory):
    """The swing was captured and identified, then judging it raised: a failed row holds the trace and the
    failure, and the appliance goes to FAULT (what the PLC and MQTT see)."""
    app = appliance_factory(appliance_doc(tmp_path / "state"))

    def broken(*args, **kwargs):
        raise RuntimeError("judging broke")

    app.app.parts.release = broken
    app.press()
    app.wait_event(lambda e: e.state.value == "FAULT", 60, what="FAULT after judging failed")
    wait_until(lambda: app.app.stored, 10, what="the failed row")
    rows = app.app.store.list(limit=None, full=True)
    assert [r.status for r in rows] == ["failed"]
    assert "judging broke" in (rows[0].error or "")
    stored = app.app.store.get(rows[0].uuid, trace=True)
    assert stored.trace_angle is not None and len(stored.trace_angle) > 100


# --- replies go where the appliance decides ---------------------------------------------------------------------

def test_an_mqtt_response_topic_outside_the_reply_namespace_is_not_honoured(tmp_path, broker, appliance_factory):
    """A client that may only set part IDs names cmd/measure (this appliance's, then another's) as its response
    topic, with 4 kB of correlation data: the reply goes to the reply topic without it; nothing fires."""
    from tests.service.publish.mqtt.test_service_mqtt_replies import BASE, V5Client

    app = appliance_factory(appliance_doc(tmp_path / "state", mqtt_port=broker.port))
    assert app.app.mqtt.subscribed_event.wait(10)
    c = V5Client(broker.port, [f"{BASE}/reply", f"{BASE}/cmd/measure", "moi/other-rig/cmd/measure"])
    try:
        c.send("part_id", {"id": "p1", "part_id": "SN-1"}, response_topic=f"{BASE}/cmd/measure",
               correlation=b"\x01" * 4096)
        c.send("part_id", {"id": "p2", "part_id": "SN-2"}, response_topic="moi/other-rig/cmd/measure",
               correlation=b"\x02")
        for cid in ("p1", "p2"):
            topic, doc, corr = c.wait_for(lambda g, cid=cid: g[1].get("id") == cid)
            assert topic == f"{BASE}/reply" and doc["status"] == "done"
        assert c.wait_for(lambda g: g[1].get("id") == "p1")[2] is None  # 4 kB are not echoed
        assert all(g[0] == f"{BASE}/reply" for g in c.got), c.got
        assert "ARMED" not in app.states()
    finally:
        c.close()


# --- names are data, not syntax ---------------------------------------------------------------------------------

HOSTILE = ["rotor\nA12", "rotor\x07A12", "rotor\x1b[2JA12", "rotor\u2028A12", "x" * 65]


@pytest.mark.parametrize("name", HOSTILE)
def test_a_hostile_name_is_refused_at_every_door_that_takes_one(tmp_path, name):
    """A line break, a bell, an escape, a Unicode line separator or an overlong name: refused in a recipe file,
    as the device id, a web user, the OPC UA user and a part ID, each saying what a name may hold."""
    from measurement.errors import InvalidInput
    from service.config.appliance import parse_config
    from service.errors import ConfigError, StartupError
    from service.parts.recipes import check_part_id, load_recipe
    from service.publish.web.auth import hash_password, read_users

    recipe = (Path(__file__).resolve().parents[2] / "examples" / "recipes" / "rotor-a12.toml").read_text()
    bad = tmp_path / "bad.toml"
    import tomli_w
    bad.write_text(recipe.replace('name = "rotor-A12"', f"name = {tomli_w.dumps({'n': name})[4:].strip()}"))
    with pytest.raises(ConfigError, match="recipe name must be"):
        load_recipe(bad)
    with pytest.raises(ConfigError, match="device id must be"):
        parse_config(appliance_doc(tmp_path / "state", device_id=name), source="test.toml")
    with pytest.raises(ConfigError, match="user name must be"):
        parse_config(appliance_doc(tmp_path / "state", opcua={"username": name, "password": "p" * 16}),
                     source="test.toml")
    users = tmp_path / "users.toml"
    users.write_text(tomli_w.dumps({"user": [{"name": name, "role": "operator", "password": hash_password("pw-123456")}]}))
    with pytest.raises(StartupError, match="user name must be"):
        read_users(users)
    with pytest.raises(InvalidInput, match="part ID must be"):
        check_part_id(name[:21])
    assert check_part_id(" SN-0042 ") == "SN-0042" and check_part_id("") == ""


def test_a_download_named_after_a_hostile_name_still_gets_a_valid_header():
    """A recipe name from a store written before the check: the export's Content-Disposition carries it
    percent-encoded, and aiohttp sends it (a line break in a header raised, and the connection dropped)."""
    from aiohttp import web

    from service.names import content_disposition

    header = content_disposition("moi-test-rig-rotor\nA\x07 \"ü\".dfq")
    assert header.isprintable() and header.isascii() and "\n" not in header
    assert "filename*=UTF-8''moi-test-rig-rotor%0AA%07%20%22%C3%BC%22.dfq" in header
    web.Response(body=b"", headers={"Content-Disposition": header})  # no ValueError


# --- the web page's live streams --------------------------------------------------------------------------------

def test_live_streams_never_lock_the_page_out_and_end_after_their_lifetime(tmp_path, appliance_factory):
    """More unauthenticated /events streams than the page has connections: only max_streams_per_client of them
    are served (the others get a 503 at once), the page and its Measure still answer, and a stream ends after
    stream_lifetime (the browser reconnects by itself)."""
    import urllib.request

    app = appliance_factory(appliance_doc(tmp_path / "state", web={
        "enabled": True, "max_connections": 8, "max_streams_per_client": 2, "stream_lifetime": 1.0}))
    web = app.app.web
    port = web.bound_port
    streams = []
    try:
        heads = []
        for _ in range(12):
            s = socket.create_connection(("127.0.0.1", port), timeout=10)
            s.sendall(b"GET /events HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")
            streams.append(s)
            heads.append(s.recv(12))
        assert sum(h.startswith(b"HTTP/1.1 200") for h in heads) == 2, heads
        assert sum(h.startswith(b"HTTP/1.1 503") for h in heads) == 10, heads
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/api/state", timeout=10) as r:
            assert r.status == 200
        token = Path(web.token_file).read_text().strip()
        req = urllib.request.Request(f"http://127.0.0.1:{port}/api/measure", method="POST",
                                     headers={"Authorization": f"Bearer {token}"})
        with urllib.request.urlopen(req, timeout=10) as r:
            assert r.status in (200, 202)
        for s, head in zip(streams, heads):
            if head.startswith(b"HTTP/1.1 200"):
                s.settimeout(30)
                while s.recv(65536):  # the stream's events, until the server ends it
                    pass
        assert web.stats()["streams"] == 0
        app.wait_done(1, 60)
    finally:
        for s in streams:
            s.close()


def test_four_addresses_with_four_streams_each_no_longer_deny_a_fifth_viewer_or_a_logged_in_user():
    """16 slots, 4 per address, all taken by 4 addresses: a fifth address's viewer gets a slot (the oldest
    stream of an address holding the most yields it), the yielded address asking again is refused (it holds its
    share), a logged-in user gets a slot from any address (the oldest anonymous stream yields), and an anonymous
    newcomer never makes a logged-in user's stream yield."""
    from service.publish.web.streams import Stream, StreamSlots

    slots = StreamSlots(16, 4)
    ended: list[Stream] = []

    def take(client: str, logged_in: bool = False) -> Stream | str:
        holder: list[Stream] = []
        got = slots.take(client, logged_in, end=lambda: ended.append(holder[0]))
        if isinstance(got, Stream):
            holder.append(got)
        return got

    crowd = [take(f"192.0.2.{a}") for a in range(1, 5) for _ in range(4)]
    assert all(isinstance(s, Stream) for s in crowd) and slots.open == 16
    viewer = take("198.51.100.7")
    assert isinstance(viewer, Stream) and ended == [crowd[0]] and slots.open == 16 and slots.yielded == 1
    slots.give_back(ended[0])  # the yielded stream's handler ends: its slot is not given twice
    assert slots.open == 16
    again = take("192.0.2.1")  # the browser asks again at once: its address holds its share now
    assert isinstance(again, str) and "none yields" in again and slots.refused == 1
    user = take("203.0.113.9", logged_in=True)  # below its share: the address holding the most yields
    assert isinstance(user, Stream) and ended == [crowd[0], crowd[4]]
    users = [take("192.0.2.2", logged_in=True) for _ in range(4)]  # a login at a crowded address
    assert all(isinstance(u, Stream) for u in users)
    assert ended[2:] == [crowd[1], crowd[5], crowd[6], crowd[7]]  # the oldest anonymous, anywhere then its own
    assert isinstance(take("192.0.2.2", logged_in=True), str)  # logged-in tabs never take turns
    assert isinstance(take("192.0.2.2"), str)
    refused = slots.refused
    for a in range(20, 40):  # many more addresses: each gets a slot only from an address holding two or more
        take(f"198.51.100.{a}")
    assert len(ended) == 6 + 7 and slots.refused == refused + 13 and slots.open == 16
    assert not any(e.logged_in for e in ended) and viewer not in ended and user not in ended
    assert sum(isinstance(take(f"198.51.100.{a}"), str) for a in range(40, 50)) == 10


def test_a_stream_that_yields_its_slot_ends_and_the_newcomer_is_served(tmp_path, appliance_factory):
    """Over loopback, from several source addresses of 127.0.0.0/8: two addresses fill the four slots, a third
    address's stream is served and the oldest stream ends at once (the server closes it)."""
    app = appliance_factory(appliance_doc(tmp_path / "state", web={
        "enabled": True, "max_streams": 4, "max_streams_per_client": 2, "stream_lifetime": 600.0}))
    web = app.app.web
    port = web.bound_port
    streams = []

    def open_from(source: str, cookie: str = "") -> bytes:
        s = socket.socket()
        s.settimeout(30)
        s.bind((source, 0))
        s.connect(("127.0.0.1", port))
        s.sendall(f"GET /events HTTP/1.1\r\nHost: 127.0.0.1\r\nCookie: {cookie}\r\n\r\n".encode())
        streams.append(s)
        head = b""
        while b"retry: 1000" not in head and not head.startswith(b"HTTP/1.1 503"):
            head += s.recv(4096)
        return head

    try:
        for source in ("127.0.0.2", "127.0.0.2", "127.0.0.3", "127.0.0.3"):
            assert open_from(source).startswith(b"HTTP/1.1 200")
        assert open_from("127.0.0.4").startswith(b"HTTP/1.1 200")  # refused (503) before
        while streams[0].recv(65536):  # the oldest stream ends: the server closes its connection
            pass
        assert open_from("127.0.0.2").startswith(b"HTTP/1.1 503")  # and asking again, it holds its share
        assert web.stats()["streams_yielded"] == 1 and web.stats()["streams"] == 4
        login = login_from("127.0.0.2", port, token=Path(web.token_file).read_text().strip())
        assert login.status == 303
        cookie = login.getheader("Set-Cookie").split(";")[0]
        assert open_from("127.0.0.2", cookie).startswith(b"HTTP/1.1 200")  # the oldest anonymous stream yields
        while streams[1].recv(65536):
            pass
        assert web.stats()["streams_yielded"] == 2 and web.stats()["streams"] == 4
    finally:
        for s in streams:
            s.close()


# --- moi run --check ------------------------------------------------------------------------------------------

def test_check_refuses_what_the_start_refuses_and_warns_of_open_opcua_doors(tmp_path, capsys):
    """--check reads the secrets as the start does: a missing trusted_clients directory, an 8-character token,
    a directory as the users file are problems; a world-readable token, anonymous or unencrypted OPC UA
    are warnings."""
    from service.cli import main

    pw = tmp_path / "pw"
    pw.write_text("opcua-secret-16ch")
    pw.chmod(0o600)

    def config(extra: str) -> str:
        path = tmp_path / "appliance.toml"
        path.write_text(f'[device]\nstate_dir = "{tmp_path / "state"}"\n[modbus]\nport = 0\n{extra}')
        return str(path)

    def check(extra: str) -> tuple[int, str]:
        status = main(["run", "--check", "--config", config(extra)])
        out = capsys.readouterr()
        return status, out.out + out.err

    opc = f'[opcua]\nport = 0\nusername = "line-7"\npassword_file = "{pw}"\n'
    status, out = check(opc + f'trusted_clients = "{tmp_path / "nowhere"}"\n[web]\nenabled = false\n')
    assert status == 2 and "trusted_clients" in out and "is not a directory" in out
    status, out = check(opc + 'anonymous = true\nallow_unencrypted = true\n[web]\nenabled = false\n')
    assert status == 0 and "WARNING  OPC UA exposure: clients without a user" in out and "unencrypted" in out
    short = tmp_path / "token"
    short.write_text("12345678")
    short.chmod(0o644)
    status, out = check(f'[web]\nenabled = true\nport = 0\ntoken_file = "{short}"\n')
    assert status == 2 and "shorter than 16 characters" in out
    short.write_text("a-long-enough-token-1234")
    status, out = check(f'[web]\nenabled = true\nport = 0\ntoken_file = "{short}"\n')
    assert status == 0 and "WARNING  web token_file" in out and "chmod 600" in out
    short.chmod(0o600)
    status, out = check(f'[web]\nenabled = true\nport = 0\ntoken_file = "{short}"\nusers_file = "{tmp_path}"\n')
    assert status == 2 and "users file" in out


# --- acknowledgements ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("damage", [b"\x00\x00\x00", b"12x\n", b"\xff\xfe garbage", b"-5\n"])
def test_a_damaged_acknowledgement_file_is_quarantined_and_owed_results_stay_owed(tmp_path, caplog, damage):
    """OPC UA's acknowledgement file (which the Modbus FIFO reads in the same format) damaged while two results
    were owed: both are still offered after the restart by OPC UA and by the Modbus FIFO, the damaged file is
    kept aside, and the log says so."""
    from service.persistence.store import Store
    from service.publish.modbus.server import ModbusServer
    from service.publish.modbus.settings import ModbusSettings
    from service.publish.opcua.server import ACKED_FILE, OpcUaServer
    from service.publish.opcua.settings import OpcUaSettings
    from tests.service.publish.modbus.test_service_registers import payload

    state = tmp_path / "state"
    state.mkdir()
    store = Store(state)
    try:
        for i in range(3):
            store.record(status="ok", trigger="test", device_id="test-rig", software_version="t", started_at=i,
                         finished_at=i + 1, result={"J": 0.01, "flags": []},
                         build_payload=lambda uuid, seq: payload(seq, uuid=uuid))
        acked = state / ACKED_FILE
        acked.write_bytes(b"1\n")  # the first result acknowledged, two owed ...
        acked.write_bytes(damage)  # ... and then the file was damaged
        server = OpcUaServer(OpcUaSettings(username="u", password="p"), "test-rig", state, store=store)
        with caplog.at_level("WARNING", logger="moi.acks"):
            server._restore()
        assert sorted(server._unacknowledged.values())[-2:] == [2, 3]
        assert (state / (ACKED_FILE + ".damaged")).read_bytes() == damage
        assert any("is damaged" in r.getMessage() for r in caplog.records)
        acked.write_bytes(damage)
        fifo = ModbusServer(ModbusSettings(host="127.0.0.1", port=0, result_handshake="ack"), acked_file=acked)
        fifo.restore_queue(store)
        assert fifo.results_queued() >= 2
    finally:
        store.close()


# --- tensor sets cut short ----------------------------------------------------------------------------------------

def test_a_tensor_set_cut_short_by_a_stop_or_a_kill_is_recorded_as_interrupted(tmp_path, appliance_factory, caplog):
    """One release of a six-orientation set, then a normal stop: the set is stored as interrupted with its
    release. The file a kill -9 would have left behind (taken before the stop) makes the next start store
    that set as interrupted and say so; the new set begins at the first orientation."""
    from service.parts.tensor_set import OPEN_SET_FILE
    from tests.service.parts.test_service_tensor_set import measure_step, progress, tensor_doc

    doc = tensor_doc(tmp_path)
    app = appliance_factory(doc)
    measure_step(app, 0)
    left = (tmp_path / "state" / OPEN_SET_FILE).read_text()  # what a kill -9 now would leave
    first = progress(app)["uuid"]
    assert app.stop() == 0
    store_sets = __import__("service.persistence.store", fromlist=["Store"]).Store(tmp_path / "state")
    try:
        sets = store_sets.tensor_sets()
    finally:
        store_sets.close()
    assert [(s["uuid"], s["status"], s["interrupted"]) for s in sets] == [(first, "aborted", True)]
    assert sum(len(v) for v in sets[0]["releases"].values()) == 1 and "1 release(s) stay stored" in sets[0]["error"]
    assert not (tmp_path / "state" / OPEN_SET_FILE).exists()

    killed = json.loads(left) | {"uuid": "00000000-0000-4000-8000-000000000001"}
    (tmp_path / "state" / OPEN_SET_FILE).write_text(json.dumps(killed))
    with caplog.at_level("WARNING", logger="moi.daemon"):
        again = appliance_factory(doc)
    assert any("was interrupted" in r.getMessage() and killed["uuid"] in r.getMessage() for r in caplog.records)
    sets = again.app.store.tensor_sets()
    assert [s.get("interrupted") for s in sets] == [True, True] and sets[0]["uuid"] == killed["uuid"]
    assert progress(again)["step"] == 1


def test_a_capture_slowed_while_clients_were_served_is_flagged():
    """Quiet captures give the reference rate; a capture during which requests passed the gates and whose
    rate fell from 139 to 84 samples/s (what a 50,000-node Read loop did) is flagged, one at 130 is not, and
    without a quiet capture to compare with there is no flag. The flag has its Modbus bit."""
    from measurement import flags as F
    from service.contention import CaptureWatch

    served = [0]
    watch = CaptureWatch(lambda: served[0])

    def capture(rate: float, requests: int) -> bool:
        watch.armed()
        served[0] += requests
        return watch.slowed({"encoder": {"rate_hz": rate, "samples": 900}})

    assert not capture(84.0, 10)  # nothing to compare with yet
    assert not capture(139.0, 0) and not capture(137.0, 0)
    assert capture(84.0, 25)
    assert not capture(130.0, 25)
    assert not capture(60.0, 0)  # slow without clients: the bus, not the appliance's doors
    assert F.CAPTURE_SLOWED in F.FLAGS and F.FLAG_BITS[F.CAPTURE_SLOWED] == 24
    assert F.flags_from_bits(F.flag_bits([F.CAPTURE_SLOWED])) == [F.CAPTURE_SLOWED]


def test_the_connection_caps_must_leave_descriptors_for_the_measurement():
    """Under the unit's 1,024 descriptors, every protocol's cap together with the reserve for the measurement
    and the store: the defaults fit; a web page allowed 512 connections does not, and --check says so."""
    from service.config.appliance import parse_config
    from service.config.check import descriptor_budget

    ok = parse_config(appliance_doc(Path("/tmp/unused"), web={"enabled": True},
                                    opcua={"username": "u", "password": "p" * 16}), source="t")
    assert descriptor_budget(ok, limit=1024).ok
    greedy = parse_config(appliance_doc(Path("/tmp/unused"), web={"enabled": True, "max_connections": 512}),
                          source="t")
    check = descriptor_budget(greedy, limit=1024)
    assert not check.ok and "lower max_connections" in check.detail


# --- the log ------------------------------------------------------------------------------------------------------

def test_what_a_client_repeats_is_logged_once_a_minute_with_a_count(tmp_path, broker, appliance_factory, caplog):
    """200 part ID commands with one id (duplicates after the first) and 200 retained commands: a line each for
    the first, the rest held back; the repeat filter of the daemon's handler says how many lines it held."""
    import logging

    from service.logs import RepeatFilter
    from tests.service.publish.mqtt.test_service_mqtt_replies import BASE, V5Client

    app = appliance_factory(appliance_doc(tmp_path / "state", mqtt_port=broker.port))
    assert app.app.mqtt.subscribed_event.wait(10)
    c = V5Client(broker.port, [f"{BASE}/reply"])
    try:
        with caplog.at_level("INFO", logger="moi.mqtt"):
            for _ in range(200):
                c.send("part_id", {"id": "same", "part_id": "SN-1"})
            for _ in range(200):
                c.client.publish(f"{BASE}/cmd/part_id", "SN-2", qos=1, retain=True).wait_for_publish(5)
            c.client.publish(f"{BASE}/cmd/part_id", "", qos=1, retain=True).wait_for_publish(5)
            c.wait_for(lambda g: g[1].get("reason") == "duplicate")
            wait_until(lambda: app.app.mqtt._say._seen.get(
                "MQTT: duplicate %s command id %s ignored", [0, 0])[1] >= 198, 30, what="the duplicates")
    finally:
        c.close()
    lines = [r.getMessage() for r in caplog.records if r.name == "moi.mqtt"]
    assert sum("duplicate" in m for m in lines) == 1 and sum("retained" in m for m in lines) <= 1, lines

    clock = [0.0]
    f = RepeatFilter(interval=60.0, clock=lambda: clock[0])
    rec = lambda msg, *args: logging.LogRecord("asyncua.server", logging.WARNING, "x", 1, msg, args, None)  # noqa: E731
    assert f.filter(rec("Closing idle connection from %s", ("127.0.0.1", 1)))
    assert not any(f.filter(rec("Closing idle connection from %s", ("127.0.0.1", p))) for p in range(2, 500))
    clock[0] = 61.0
    last = rec("Closing idle connection from %s", ("127.0.0.1", 501))
    assert f.filter(last) and "(and 498 more like it in the last 60 s)" in last.getMessage()
