"""What the appliance answers to a command, on every surface: one table of outcomes and reasons.

A command (a trigger, an abort, a recipe selection ...) from the Modbus command register or MQTT is queued with a
``reply`` callable; the daemon's main loop calls it with a ``CommandReply`` once it has acted: accepted
(a trigger: a measurement starts), refused (with the reason; nothing changed), done (a trigger: its result
is stored; any other command: applied) or failed (a trigger's measurement ended in FAULT or was aborted).
Modbus shows the reason's code in register ``command_reason``, MQTT its name in the reply message. (The
OPC UA server takes no commands: its methods read and acknowledge results.)
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any, Callable

#: an absolute path in a reply's words (not a URL's: no ':' or '/' before it); its last part is what a reply keeps
_PATH = re.compile(r"(?<![\w.:/~])/(?:[^\s/'\"(),;:]+/)*([^\s/'\"(),;:]*)")


def without_paths(text: str) -> str:
    """``text`` with each absolute file-system path cut to its last part: a reply goes to every client of a
    broker or a server, the appliance's folders are not theirs to know (the log keeps the whole path)."""
    return _PATH.sub(lambda m: m.group(1) or "…", text)


@dataclass(frozen=True)
class Reason:
    """Why a command was refused: its number (Modbus register ``command_reason``) and its words."""

    code: int
    words: str


#: every reason a command is refused or fails, by name (the name is the MQTT reply's ``reason``)
REASONS: dict[str, Reason] = {
    "busy": Reason(1, "a measurement runs: the part cannot change, a trigger waits for the result"),
    "unknown_recipe": Reason(2, "no recipe has this name or number"),
    "malformed": Reason(3, "the command's data is malformed (a part ID outside printable ASCII or too long, "
                           "a missing field, not JSON where JSON is needed)"),
    "fault": Reason(4, "the appliance is in FAULT: acknowledge it first (abort / acknowledge_fault)"),
    "store_unwritable": Reason(5, "the result store cannot be written: no measurement may start"),
    "nothing_to_abort": Reason(6, "no measurement runs and no FAULT is latched"),
    "not_ready": Reason(7, "the appliance is not IDLE (starting, stopping or between states)"),
    "no_tensor_set": Reason(8, "no tensor set runs"),
    "unknown_command": Reason(9, "the command is not one the appliance knows"),
    "measurement_failed": Reason(10, "the measurement ended in FAULT or was aborted: no result"),
    "duplicate": Reason(11, "a command with this id was received already (QoS 1 may deliver twice): done once"),
    "calibration_due": Reason(12, "the rig's calibration expired, or its newest check standard failed: every "
                                  "result would be INVALID, so no measurement starts (the detail says what to do "
                                  "and whom to call)"),
}

#: whom an operator calls when the calibration refuses a measurement, unless ``[web] contact`` names someone
CONTACT = "the quality engineer on shift"


def fault_refusal(fault: str | None, contact: str) -> str:
    """The words every door says to a trigger refused in FAULT: what is wrong, and who acknowledges it (an
    operator cannot: the quality role, or the PLC's acknowledge, does once the cause is fixed)."""
    return (f"not measured: the appliance is in FAULT ({fault or 'no reason recorded'}); nothing is measured until "
            f"the fault is acknowledged: ask {contact} to acknowledge it once the cause is fixed")


#: the statuses of a reply, in the order a trigger goes through them
STATUSES = ("accepted", "refused", "done", "failed")


@dataclass(frozen=True)
class CommandReply:
    """The outcome of a command. status: one of STATUSES. reason: a REASONS name (refused, failed) or None.
    detail: the words for a person. data: what the outcome produced (a trigger's result: uuid, seq)."""

    command: str
    status: str
    reason: str | None = None
    detail: str = ""
    data: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.status not in STATUSES:
            raise ValueError(f"reply status {self.status!r}; expected one of {STATUSES}")
        if self.reason is not None and self.reason not in REASONS:
            raise ValueError(f"reply reason {self.reason!r}; expected one of {tuple(REASONS)}")

    @property
    def reason_code(self) -> int:
        """The reason's number (0: none)."""
        return REASONS[self.reason].code if self.reason is not None else 0

    def to_dict(self) -> dict[str, Any]:
        return {"command": self.command, "status": self.status, "reason": self.reason,
                "detail": without_paths(self.detail) or (REASONS[self.reason].words if self.reason else ""),
                **self.data}


#: what a command's source hands the daemon to hear the outcome (called on the main loop thread; must not block)
ReplyTo = Callable[[CommandReply], None]
