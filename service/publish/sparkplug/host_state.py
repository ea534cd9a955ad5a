"""The primary host application's STATE (Sparkplug B 3.0, ``spBv1.0/STATE/<host id>``), read as untrusted input.

Any client of the broker can publish a STATE. The edge node acts on one only when it is the specification's
JSON, ``{"online": true | false, "timestamp": ms}``, and its timestamp lies between 0 and this clock's now plus
a tolerance: the node ignores a STATE older than the newest it has acted on (a late copy from an earlier
session of the host), so a single stamp far in the future would otherwise make every genuine STATE "older"
and hold the births until a restart. Whatever the payload (a number beyond any integer, ``Infinity``,
garbage, a list), reading it raises ``HostStateRefused`` with the reason and nothing else.

Sparkplug 2.2 hosts (``STATE/<host id>`` with the text ``ONLINE`` / ``OFFLINE``) are not read: that message
has no timestamp, so a stale retained copy cannot be told from the current one (docs/service.md).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

from service.errors import HostStateRefused

#: a STATE longer than this is not the specification's (its JSON is some 40 bytes), bytes
MAX_STATE_BYTES = 1024
_EXPECTED = 'expected JSON {"online": true | false, "timestamp": ms since 1970}'


@dataclass(frozen=True)
class HostState:
    """A STATE the edge node acts on: the host online or not, stamped ``timestamp`` (ms since 1970, UTC)."""

    online: bool
    timestamp: int


def read_state(raw: bytes, now_ms: int, tolerance_ms: int) -> HostState:
    """The STATE ``raw`` as the node acts on it; ``HostStateRefused`` (saying why) for anything else,
    a timestamp after ``now_ms + tolerance_ms`` included."""
    if len(raw) > MAX_STATE_BYTES:
        raise HostStateRefused(f"{len(raw)} bytes (at most {MAX_STATE_BYTES}); {_EXPECTED}")
    try:
        doc = json.loads(raw)
    except (ValueError, RecursionError) as exc:  # UnicodeDecodeError is a ValueError
        raise HostStateRefused(f"not JSON ({type(exc).__name__}); {_EXPECTED}") from None
    if not isinstance(doc, dict):
        raise HostStateRefused(f"a JSON {type(doc).__name__}; {_EXPECTED}")
    online, stamp = doc.get("online"), doc.get("timestamp")
    if not isinstance(online, bool):
        raise HostStateRefused(f"online is {_shown(online)}; {_EXPECTED}")
    if isinstance(stamp, bool) or not isinstance(stamp, (int, float)) or \
            (isinstance(stamp, float) and not (math.isfinite(stamp) and stamp.is_integer())):
        raise HostStateRefused(f"timestamp is {_shown(stamp)}; {_EXPECTED}")
    shown, stamp = _shown(stamp), int(stamp)
    if stamp < 0:
        raise HostStateRefused(f"timestamp {shown} is before 1970; {_EXPECTED}")
    if stamp > now_ms + tolerance_ms:
        ahead = f"{(stamp - now_ms) / 1000:.3g} s" if stamp < 1 << 62 else "centuries"
        raise HostStateRefused(f"timestamp {shown} is {ahead} ahead of this clock "
                               f"(at most {tolerance_ms / 1000:g} s, [sparkplug] state_tolerance): the host's clock "
                               "or this appliance's is wrong (NTP?), or the STATE is not the host's")
    return HostState(online, stamp)


def _shown(value: object) -> str:
    """A value of the payload as a log line shows it: short, whatever it is."""
    text = json.dumps(value) if not isinstance(value, float) or math.isfinite(value) else str(value)
    return text if len(text) <= 40 else text[:37] + "..."
