"""mosquitto's own command-line clients (Debian package mosquitto-clients) as an integrator runs them: an MQTT
stack independent of paho, reading and writing the appliance's topics."""

from __future__ import annotations

import json
import shutil
import subprocess
import threading
import time
from typing import Any, Callable

from tests.components import missing

SUB, PUB = shutil.which("mosquitto_sub"), shutil.which("mosquitto_pub")


def require_clients() -> None:
    if SUB is None or PUB is None:
        missing("mosquitto_sub / mosquitto_pub not found (Debian package mosquitto-clients; `make test` installs it)")


def mosquitto_pub(port: int, topic: str, message: str | None, *, retain: bool = False, version: str = "mqttv5") -> None:
    """One message (None: an empty one, as `-n` sends), QoS 1; fails unless the client exits 0 within 20 s."""
    args = [str(PUB), "-h", "127.0.0.1", "-p", str(port), "-V", version, "-q", "1", "-t", topic]
    args += ["-n"] if message is None else ["-m", message]
    args += ["-r"] if retain else []
    done = subprocess.run(args, capture_output=True, timeout=20)
    assert done.returncode == 0, done.stderr.decode(errors="replace")


class MosquittoSub:
    """``mosquitto_sub -F %j`` in the background: every message as JSON (topic, retain, payload), read by a thread.
    It exits after ``limit`` s at most (``-W``)."""

    def __init__(self, port: int, topics: list[str], limit: float = 120) -> None:
        # line-buffered (coreutils' stdbuf): into a pipe the client's output is otherwise held in a 4 kB buffer
        args = ["stdbuf", "-oL", str(SUB), "-h", "127.0.0.1", "-p", str(port), "-V", "mqttv5", "-q", "1", "-d", "-F", "%j",
                "-W", str(int(limit))]
        for t in topics:
            args += ["-t", t]
        self.proc = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        self.messages: list[dict[str, Any]] = []
        self._subscribed = False
        self._cond = threading.Condition()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()
        self.wait(lambda s: s._subscribed, 10, "mosquitto_sub's SUBACK")

    def _read(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:  # -d: the client's debug lines; -F %j: one JSON object per message
            with self._cond:
                if line.startswith("{"):
                    self.messages.append(json.loads(line))
                elif "received SUBACK" in line:
                    self._subscribed = True
                self._cond.notify_all()

    def on(self, suffix: str) -> list[dict[str, Any]]:
        with self._cond:
            return [m for m in self.messages if m["topic"].endswith(suffix)]

    def payloads(self, suffix: str) -> list[Any]:
        """The JSON payloads on topics ending in ``suffix`` (mosquitto_sub prints a JSON payload as JSON)."""
        return [m["payload"] if not isinstance(m["payload"], str) else json.loads(m["payload"]) for m in self.on(suffix)]

    def wait(self, predicate: Callable[["MosquittoSub"], Any], timeout: float, what: str) -> Any:
        deadline = time.monotonic() + timeout
        with self._cond:
            while not (value := predicate(self)):
                left = deadline - time.monotonic()
                if left <= 0 or (self.proc.poll() is not None and not self._reader.is_alive()):
                    raise AssertionError(f"timed out after {timeout} s waiting for {what}; got {self.messages!r:.3000}")
                self._cond.wait(min(left, 0.5))
            return value

    def close(self) -> None:
        if self.proc.poll() is None:
            self.proc.terminate()
        self.proc.wait(10)
        self._reader.join(5)
        if self.proc.stdout is not None:
            self.proc.stdout.close()
