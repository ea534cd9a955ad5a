"""The commands the appliance takes, in one table: each one's name, what it does, the data it reads and how
the daemon acts on it.

A command comes from the push button, a Modbus coil or register, an MQTT topic, the web page or the command
line; every surface names it by the constant below (the MQTT topic under ``cmd/`` is ``Command.topic``) and
queues it with ``Appliance.command``. The daemon looks the name up here and acts by ``Command.act``; a name
not in the table is refused as ``unknown_command`` (``service.publish.replies.REASONS``). What a command
answers is in ``service.publish.replies``.
"""

from __future__ import annotations

from dataclasses import dataclass

TRIGGER = "trigger"
ABORT = "abort"
ACKNOWLEDGE_FAULT = "acknowledge_fault"
RECIPE = "recipe"
PART_ID = "part_id"
SET = "set"
SET_REDO = "set_redo"
SET_SKIP = "set_skip"
SET_ABORT = "set_abort"
TYPE1 = "type1"

#: how the daemon acts on a command: ``part`` applies its data (recipe, part ID) and is done; ``measure``
#: starts a measurement (its data applied first); ``stop`` aborts the measurement or acknowledges a FAULT;
#: ``set`` is an operator action of the guided tensor set; ``study`` starts or aborts a guided gauge study
ACTS = ("part", "measure", "stop", "set", "study")

#: the keys of a command's data that say which part is measured (refused while a measurement runs)
PART_DATA = ("part_id", "recipe")

#: the source of a command from the web page: ``web:<name>`` for a named user, ``web`` for the token's login
WEB = "web"


def web_source(user: str | None) -> str:
    """The source a web user's commands are recorded with (the stored trigger of the runs they start)."""
    return f"{WEB}:{user}" if user else WEB


def operator_of(source: str) -> str:
    """Who measured, as a stored run records it (the appraiser of a Gauge R&R): the named web user who pressed
    Measure, else the door that started it ("button", "modbus", "mqtt", "sparkplug", "cli", "web")."""
    door, named, user = source.partition(":")
    return user if door == WEB and named and user else source


def source_words(source: str) -> str:
    """Who sent a command, in words: "op on the web page", "the web page (token login)", else the door."""
    door, named, user = source.partition(":")
    if door == WEB:
        return f"{user} on the web page" if named and user else "the web page (token login)"
    return source


@dataclass(frozen=True)
class Command:
    """One command. does: its words. act: one of ACTS. data: the keys of its data. topic: its MQTT topic
    under ``<prefix>/<device_id>/cmd/`` (None: not taken over MQTT). set_action: the tensor set action a
    ``set`` command without data stands for (the Modbus coils)."""

    does: str
    act: str
    data: tuple[str, ...] = ()
    topic: str | None = None
    set_action: str | None = None

    def __post_init__(self) -> None:
        if self.act not in ACTS:
            raise ValueError(f"command act {self.act!r}; expected one of {ACTS}")

    @property
    def sets_part(self) -> bool:
        """Its data may select the recipe or set the part ID (refused while a measurement runs)."""
        return any(k in PART_DATA for k in self.data)


#: every command the appliance takes, by name
COMMANDS: dict[str, Command] = {
    TRIGGER: Command("start one measurement (data may carry the part ID and the recipe, applied first)",
                     "measure", PART_DATA, topic="measure"),
    ABORT: Command("abort the running measurement, or acknowledge a FAULT", "stop", topic="abort"),
    ACKNOWLEDGE_FAULT: Command("acknowledge a FAULT", "stop"),
    RECIPE: Command("select the recipe (name or number; 0 or none deselects) and/or set the part ID", "part",
                    PART_DATA, topic="recipe"),
    PART_ID: Command("set the part ID of the next measurements", "part", (PART_ID,), topic="part_id"),
    SET: Command("an operator action of the guided tensor set (data action: redo | skip | abort, and "
                 "orientation)", "set", ("action", "orientation"), topic="set"),
    SET_REDO: Command("tensor set: measure the current orientation again (or the previous one)", "set",
                      set_action="redo"),
    SET_SKIP: Command("tensor set: skip the current orientation", "set", set_action="skip"),
    SET_ABORT: Command("tensor set: abort the set (its releases stay stored)", "set", set_action="abort"),
    TYPE1: Command("a Type 1 gauge study of the active recipe's reference part (data action: start | abort; "
                   "start: reference and tolerance in kg·m², count)", "study",
                   ("action", "reference", "tolerance", "count")),
}

#: MQTT topic tail → command name
BY_TOPIC: dict[str, str] = {c.topic: name for name, c in COMMANDS.items() if c.topic is not None}
