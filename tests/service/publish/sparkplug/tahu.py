"""Eclipse Tahu's JavaScript Sparkplug B codec (npm ``sparkplug-payload``, run by Node.js from the distribution): the
payloads as a Node.js host application decodes them, an implementation independent of the appliance's and of
pysparkplug. ``make node`` installs it into tests/node/sparkplug/; ``decode.js`` there does the decoding."""

from __future__ import annotations

import base64
import json
import shutil
import subprocess
from typing import Any

from tests.components import missing
from tests.service.conftest import REPO

NODE = shutil.which("node") or shutil.which("nodejs")
HERE = REPO / "tests" / "node" / "sparkplug"


def require_tahu() -> None:
    if NODE is None or not (HERE / "node_modules" / "sparkplug-payload").is_dir():
        missing("Node.js or Tahu's sparkplug-payload missing (`make node` installs it into tests/node/sparkplug/)")


def tahu_decode(messages: list[tuple[str, bytes]]) -> list[dict[str, Any]]:
    """Each (topic, payload) decoded by Tahu's codec: {"topic", "timestamp", "seq", "metrics": [{"name", "alias",
    "type", "value", "timestamp", "isHistorical", "properties"}]}; 64-bit integers come as decimal strings."""
    doc = json.dumps([{"topic": t, "payload": base64.b64encode(raw).decode()} for t, raw in messages])
    done = subprocess.run([str(NODE), str(HERE / "decode.js")], input=doc, capture_output=True, text=True, timeout=60,
                          cwd=HERE)
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(done.stdout)
