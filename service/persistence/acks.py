"""What a reader of the results (the PLC over Modbus, the OPC UA clients) has acknowledged, kept across restarts.

One small text file per reader in the state directory, written atomically at each acknowledgement:

    <through>            every result with seq ≤ through is acknowledged ...
    <seq> <seq> ...      ... except these (optional line: a reader that acknowledges out of order)

A result with seq > through is not acknowledged. The Modbus FIFO acknowledges in order, so its file holds
the first line only; OPC UA's AcknowledgeResults takes any results, so its file may hold the second. The
results themselves stay in the store: a restart reads them again by their sequence numbers.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from service.sources.files import write_text_atomic


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
        """The kept state; None when there is none (the reader's first start) or it cannot be read."""
        try:
            lines = self.path.read_text(encoding="ascii").split("\n")
            through = int(lines[0].strip())
            pending = frozenset(int(s) for s in lines[1].split()) if len(lines) > 1 else frozenset()
        except (OSError, ValueError, UnicodeDecodeError):
            return None
        return AckState(through, frozenset(s for s in pending if s <= through))

    def write(self, state: AckState) -> None:
        """Keep ``state`` (OSError when the file cannot be written)."""
        text = f"{int(state.through)}\n"
        if state.pending:
            text += " ".join(str(s) for s in sorted(state.pending)) + "\n"
        write_text_atomic(self.path, text)
