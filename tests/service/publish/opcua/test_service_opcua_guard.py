"""The OPC UA server before and after a login: what a peer may cost the appliance (``guard``), against the
daemon's server on loopback. One appliance for the module (its server also offers the unencrypted endpoint:
no RSA work per session); the attack with the unit's file limit runs the daemon as systemd does."""

from __future__ import annotations

import asyncio
import socket
import struct

import pytest
from asyncua import Client, ua

from tests.service.conftest import RunningAppliance, appliance_doc, wait_until

# --- OPC UA before and after a login --------------------------------------------------------------------------

OPC_USER, OPC_PASSWORD = "line-7", "s3cret-pw"


@pytest.fixture(scope="module")
def opc(tmp_path_factory):
    """An appliance whose OPC UA server also offers the unencrypted endpoint (no RSA work per session: cheap)."""
    base = tmp_path_factory.mktemp("opcua-doors")
    pw = base / "opcua-password"
    pw.write_text(OPC_PASSWORD + "\n", encoding="utf-8")
    pw.chmod(0o600)
    doc = appliance_doc(base / "state", opcua={"host": "127.0.0.1", "port": 0, "username": OPC_USER,
                                               "password_file": str(pw), "allow_unencrypted": True,
                                               "max_connections": 8, "max_nodes_per_request": 100})
    app = RunningAppliance(doc)
    try:
        yield app
    finally:
        app.stop()


async def _client(app, user: str = OPC_USER, password: str = OPC_PASSWORD) -> Client:
    c = Client(app.app.opcua.endpoint, timeout=10)
    c.set_user(user)
    c.set_password(password)
    await c.connect()
    return c


def _closed_within(s: socket.socket, payload: bytes, budget: int) -> bool:
    """Send ``payload`` until ``budget`` bytes went out; True once the server closed the connection."""
    sent = 0
    s.settimeout(10)
    try:
        while sent < budget:
            s.sendall(payload)
            sent += len(payload)
        s.shutdown(socket.SHUT_WR)
        return s.recv(1) == b""  # the server closes (it would wait for the rest of a 4 GB body otherwise)
    except (ConnectionResetError, BrokenPipeError):
        return True
    except TimeoutError:
        return False


def test_an_opcua_chunk_announcing_4_gb_is_refused_on_its_header(opc):
    """Before any login: a UA TCP header that announces a 4 GB body, then zeros. The server closes the connection
    at once instead of buffering the body; a client is served afterwards."""
    app = opc
    port = app.app.opcua.bound_port
    with socket.create_connection(("127.0.0.1", port), timeout=10) as s:
        s.sendall(b"HELF" + struct.pack("<I", 0xFFFFFFF0))
        assert _closed_within(s, bytes(65536), 8 * 1024 * 1024)
    assert app.app.opcua.health()["oversized_chunks"] >= 1

    async def run():
        c = await _client(app)
        try:
            return await c.nodes.server_state.read_value()
        finally:
            await c.disconnect()

    assert asyncio.run(run()) == ua.ServerState.Running


def test_an_opcua_read_naming_too_many_nodes_is_refused(opc):
    """A Read of more nodes than max_nodes_per_request is BadTooManyOperations; one within it is answered."""
    app = opc

    async def run():
        c = await _client(app)
        try:
            node = c.nodes.server_state
            assert len(await c.read_values([node] * 100)) == 100
            with pytest.raises(ua.UaStatusCodeError) as err:
                await c.read_values([node] * 5000)
            assert err.value.code == ua.StatusCodes.BadTooManyOperations
        finally:
            await c.disconnect()

    asyncio.run(run())
    assert app.app.opcua.health()["too_many_nodes"] >= 1


def test_1100_idle_opcua_connections_neither_lock_the_plc_out_nor_lose_the_measurement(tmp_path):
    """The daemon with the unit's descriptor limit (1024): 1,100 connections to the OPC UA port that never say a
    word. The PLC still reads and triggers, and the measurement is stored, not FAULTed for want of a descriptor."""
    import resource

    from service.publish.modbus import registers as R
    from tests.service.conftest import free_port, moi_subprocess, port_open, write_toml
    from tests.service.test_service_hardening import _plc_image, _plc_trigger

    mb_port, ua_port = free_port(), free_port()
    pw = tmp_path / "opcua-password"
    pw.write_text(OPC_PASSWORD, encoding="utf-8")
    pw.chmod(0o600)
    doc = appliance_doc(tmp_path / "state", modbus_port=mb_port,
                        opcua={"host": "127.0.0.1", "port": ua_port, "username": OPC_USER, "password_file": str(pw)})
    cfg = write_toml(tmp_path / "appliance.toml", doc)
    daemon = moi_subprocess(["run", "--config", str(cfg)],
                            preexec_fn=lambda: resource.setrlimit(resource.RLIMIT_NOFILE, (1024, 1024)))
    flood: list[socket.socket] = []
    try:
        wait_until(lambda: (port_open(mb_port) and port_open(ua_port)) or daemon.poll() is not None, 120,
                   what="the daemon's ports")
        assert daemon.poll() is None
        for _ in range(1100):
            try:
                flood.append(socket.create_connection(("127.0.0.1", ua_port), timeout=5))
            except OSError:
                break
        assert len(flood) > 1024, f"only {len(flood)} attack connections: the attack proved nothing"
        assert _plc_image(mb_port)["state"] == R.STATE_CODES["IDLE"]
        _plc_trigger(mb_port)
        image = wait_until(lambda: (lambda i: i if i["seq"] == 1 else None)(_plc_image(mb_port)), 60,
                           what="the result in the registers")
        assert image["state"] != R.STATE_CODES["FAULT"] and image["J"] > 0
    finally:
        for s in flood:
            s.close()
        daemon.terminate()
        _, err = daemon.communicate(timeout=30)
    assert b"Too many open files" not in err, err[-2000:]
    assert b"INFO asyncua" not in err  # asyncua's chatter (some 10 lines a connection) at WARNING
    assert len(err) < 20_000, f"{len(err)} bytes of log for the flood: {err[-2000:]!r}"


def test_opcua_requests_during_a_capture_wait_their_turn(opc):
    """While the sensor is read, an authenticated client's reads pass the capture's gate one at a time (the
    measurement's priority, as on the web page); the measurement completes."""
    app = opc
    g = app.app.opcua.guard
    before = g.gated
    n_done = sum(1 for e in app.events if e.state.value == "IDLE" and e.previous.value == "PUBLISHING")

    async def run():
        c = await _client(app)
        try:
            node = c.nodes.server_state
            app.press()
            while "IDENTIFYING" not in app.states()[-8:] and "FAULT" not in app.states()[-8:]:
                await c.read_values([node] * 50)
        finally:
            await c.disconnect()

    asyncio.run(run())
    app.wait_done(n_done + 1, 60)
    assert g.gated > before


def test_opcua_password_guessing_is_slowed_then_throttled_and_the_right_password_still_gets_in(opc, monkeypatch,
                                                                                               caplog):
    """Wrong logins from one host: each later message of that host before a login waits its turn; after
    LOCKOUT_AFTER of them the host is throttled (its messages wait in its own line), yet a client there with the
    right password still logs in (a lockout refused it with the guesser); the log names the peer."""
    from service.publish.opcua import guard as G

    app = opc
    g = app.app.opcua.guard
    monkeypatch.setattr(g.logins, "after", 3)
    monkeypatch.setattr(G, "GUESS_DELAY", 0.01)
    monkeypatch.setattr(G, "THROTTLE_DELAY", 0.01)
    before = g.health()

    async def attempt(password: str) -> bool:
        try:
            c = await _client(app, password=password)
        except Exception:
            return False
        await c.disconnect()
        return True

    try:
        with caplog.at_level("WARNING", logger="moi.opcua"):
            assert [asyncio.run(attempt(f"guess-{i}")) for i in range(3)] == [False] * 3
            assert g.logins.locked_for("127.0.0.1") > 0
            assert asyncio.run(attempt(OPC_PASSWORD))  # throttled, not refused: the right password gets in
            assert not asyncio.run(attempt("guess-3"))
        after = g.health()
        assert after["wrong_logins"] - before["wrong_logins"] == 4
        assert after["throttled"] > before["throttled"]
        assert after["delayed_before_login"] > before["delayed_before_login"]
        assert any("127.0.0.1 throttled" in r.getMessage() for r in caplog.records), caplog.text
    finally:
        g.logins.lift(lambda host: True)


def test_an_opcua_host_is_throttled_for_a_while_only_on_wrong_logins_close_together():
    """The guard's clock moved by hand: wrong logins spread wider than LOCKOUT_WINDOW throttle nobody; LOCKOUT_AFTER
    within it throttle that host alone, for LOCKOUT_SECONDS, and never for longer than a login may take."""
    from service.publish.opcua.guard import LOCKOUT_AFTER, LOCKOUT_SECONDS, LOCKOUT_WINDOW, Guard, Limits

    now = [0.0]
    g = Guard(Limits(login_timeout=4.0), clock=lambda: now[0])
    for _ in range(LOCKOUT_AFTER):
        g.login_failed("192.0.2.66")
        now[0] += LOCKOUT_WINDOW / (LOCKOUT_AFTER - 2)
    assert g.logins.locked_for("192.0.2.66") == 0
    for _ in range(LOCKOUT_AFTER):
        g.login_failed("192.0.2.66")
    assert g.logins.locked_for("192.0.2.66") == LOCKOUT_SECONDS and g.logins.locked_for("192.0.2.10") == 0
    assert g.throttle_delay() == 0.5  # an eighth of the login timeout
    now[0] += LOCKOUT_SECONDS
    assert g.logins.locked_for("192.0.2.66") == 0
