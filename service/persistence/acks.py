"""What a reader of the results (the PLC over Modbus, the OPC UA clients) has acknowledged, kept across restarts.

One small text file per reader in the state directory, written atomically at each acknowledgement:

    <through>            every result with seq ≤ through is acknowledged ...
    <seq> <seq> ...      ... except these (optional line: a reader that acknowledges out of order)

A result with seq > through is not acknowledged. The Modbus FIFO acknowledges in order, so its file holds
the first line only; OPC UA's AcknowledgeResults takes any results, so its file may hold the second. The
results themselves stay in the store: a restart reads them again by their sequence numbers.

A damaged file (a torn write, a full disk, a hand edit) is not a first start: it is moved aside as
``<name>.damaged``, said in the log, and read as "nothing acknowledged", so the results still in the store
are offered again (a reader may get one twice; it never loses one it was owed).
"""

from __future__ import annotations

import logging
import os
from dataclasses import dataclass
from pathlib import Path

from service.sources.files import write_text_atomic

log = logging.getLogger("moi.acks")


@dataclass(frozen=True)
class AckState:
    """Acknowledged: every seq ≤ ``through`` except those in ``pending``."""

    through: int
    pending: frozenset[int] = frozenset()

    def acknowledged(self, seq: int) -> bool:
        return seq <= self.through and seq not in self.pending


class AckFile:
    """One reader's acknowledgements on disk (``path``)."""

    def __init__(self, path: Path) -> None:
        self.path = Path(path)

    def read(self) -> AckState | None:
        """The kept state; None when there is none (the reader's first start). A damaged file: quarantined and
        read as nothing acknowledged (``AckState(0)``)."""
        try:
            lines = self.path.read_text(encoding="ascii").split("\n")
            through = int(lines[0].strip())
            pending = frozenset(int(s) for s in lines[1].split()) if len(lines) > 1 else frozenset()
            if through < 0 or any(s < 0 for s in pending):
                raise ValueError(f"a negative sequence number ({through})")
        except FileNotFoundError:
            return None
        except (OSError, ValueError, UnicodeDecodeError) as exc:
            return self._quarantine(exc)
        return AckState(through, frozenset(s for s in pending if s <= through))

    def _quarantine(self, why: Exception) -> AckState:
        aside = self.path.with_name(self.path.name + ".damaged")
        try:
            os.replace(self.path, aside)
            kept = f"moved to {aside}"
        except OSError as exc:
            kept = f"left in place ({exc.strerror})"
        log.warning("the acknowledgement file %s is damaged (%s): %s; every result still in the store is offered "
                    "again", self.path, type(why).__name__, kept)
        return AckState(0)

    def write(self, state: AckState) -> None:
        """Keep ``state`` (OSError when the file cannot be written)."""
        text = f"{int(state.through)}\n"
        if state.pending:
            text += " ".join(str(s) for s in sorted(state.pending)) + "\n"
        write_text_atomic(self.path, text)
