"""The canonical JSON text of a payload: what the store keeps and the outbox hands MQTT, byte for byte."""

from __future__ import annotations

import json
from typing import Any, Mapping


def dumps(payload: Mapping[str, Any]) -> str:
    """Canonical JSON text of a payload (what MQTT carries and the store keeps)."""
    return json.dumps(payload, ensure_ascii=False, allow_nan=False, separators=(",", ":"))
