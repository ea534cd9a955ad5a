"""While the sensor is read, pages wait their turn (one at a time); the live stream and actions never wait."""

from __future__ import annotations

import asyncio
import contextlib

from aiohttp import web
from aiohttp.test_utils import TestClient, TestServer

from service.publish.web.priority import CaptureFirst


async def _serve_two_at_once(capturing: bool, method: str = "GET", path: str = "/page") -> tuple[int, int]:
    """Two requests sent together; (most handlers running at once, requests gated)."""
    gate = CaptureFirst(lambda: capturing)
    active, most, both_in = 0, 0, asyncio.Event()

    async def handler(request: web.Request) -> web.Response:
        nonlocal active, most
        active += 1
        most = max(most, active)
        if active == 2:
            both_in.set()
        # without the gate the first waits here for the second; with it, the wait runs out alone
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(both_in.wait(), 0.5 if capturing and method == "GET" and path == "/page" else 30)
        active -= 1
        return web.Response(text="ok")

    app = web.Application(middlewares=[gate.middleware])
    app.router.add_route(method, path, handler)
    async with TestClient(TestServer(app, host="127.0.0.1")) as client:
        answers = await asyncio.gather(*(client.request(method, path) for _ in range(2)))
        assert [r.status for r in answers] == [200, 200]
    return most, gate.gated


def test_pages_are_served_one_at_a_time_during_a_capture():
    assert asyncio.run(_serve_two_at_once(capturing=True)) == (1, 2)


def test_outside_a_capture_pages_are_served_together():
    assert asyncio.run(_serve_two_at_once(capturing=False)) == (2, 0)


def test_actions_and_the_live_stream_never_wait_for_the_gate():
    assert asyncio.run(_serve_two_at_once(capturing=True, method="POST")) == (2, 0)
    assert asyncio.run(_serve_two_at_once(capturing=True, path="/events")) == (2, 0)
