"""What the page says about states and quality flags, in words a technician reads."""

from __future__ import annotations

from measurement.flags import describe
from service.states import STATES

#: sequencer state → what is happening
STATE_WORDS: dict[str, str] = {name: s.words for name, s in STATES.items()}


def flag_words(flags) -> list[tuple[str, str]]:
    """(flag, its meaning) for each flag; the meanings are the one table in ``measurement.flags``."""
    return [(f, describe(f)) for f in flags or ()]


def flag_name(flag: str) -> str:
    """A flag's identifier as words ("model_ambiguous" → "model ambiguous"): what a page shows, the identifier
    kept for its tooltip."""
    return flag.replace("_", " ")
