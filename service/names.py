"""Names are data, not syntax: the one table of the names that reach an MQTT topic, an HTTP header, a file name,
a Modbus block, an OPC UA string, an export, a terminal or a page, and what each may hold.

Whatever the door a name comes in by (the configuration, a recipe file, the users file, an MQTT or Modbus
command, the web page, OPC UA, a command's option, a calibration file, a rig file), it is checked here:
printable characters only (no line break, bell or escape: a control character in a recipe name made the broker
drop the appliance's connection at the retained ``spc/<name>`` publish, and broke the download's
``Content-Disposition``; an escape sequence in a name printed by a command is run by the terminal), a length
limit, and no character that is syntax where the name goes (``/``, ``#``, ``+`` in an MQTT topic level).
"""

from __future__ import annotations

from dataclasses import dataclass
from urllib.parse import quote

from measurement.errors import InvalidInput


@dataclass(frozen=True)
class NameRule:
    """What one kind of name may hold."""

    what: str  # the name's name, as a message says it
    length: int  # at most this many characters
    forbidden: str = ""  # characters that are syntax where the name goes
    ascii: bool = False  # printable ASCII only (a Modbus block of 2 characters per register)
    reaches: str = ""  # where the name goes (why the rule)

    def problem(self, text: object) -> str | None:
        """Why ``text`` is not such a name, or None."""
        if not isinstance(text, str):
            return f"{self.what} must be text, got {type(text).__name__}"
        if not text or text != text.strip():
            return f"{self.what} must be 1–{self.length} characters without surrounding blanks, got {text!r}"
        if len(text) > self.length:
            return f"{self.what} must be at most {self.length} characters, got {len(text)}"
        bad = [ch for ch in text if not ch.isprintable() or ch in self.forbidden
               or (self.ascii and not 32 <= ord(ch) < 127)]
        if bad:
            allowed = "printable ASCII" if self.ascii else "printable characters"
            without = f" without {', '.join(repr(c) for c in self.forbidden)}" if self.forbidden else ""
            refused = ", ".join(f"{ch!r} (character {text.index(ch) + 1})" for ch in dict.fromkeys(bad))
            return f"{self.what} must be {allowed}{without} (it reaches {self.reaches}), got {text!r}: {refused} refused"
        return None


#: every name that leaves the appliance in a topic, a header, a file name or an export
NAMES: dict[str, NameRule] = {
    "recipe": NameRule("recipe name", 64, "/#+", reaches="the MQTT topic spc/<name>, export file names and OPC UA"),
    "part_id": NameRule("part ID", 20, ascii=True, reaches="the Modbus part ID block, MQTT, OPC UA and exports"),
    "device_id": NameRule("device id", 64, "/#+ ", reaches="every MQTT topic, Home Assistant's ids, OPC UA and "
                          "export file names"),
    "user": NameRule("user name", 64, "$", reaches="the web page, the stored trigger web:<name> and OPC UA"),
    "person": NameRule("the name of who calibrated", 64, reaches="the terminal, the rig's calibration history and "
                       "the web page"),
    "reference": NameRule("reference name", 80, reaches="the terminal, the rig file, its calibration history and "
                          "the web page"),
    "certificate": NameRule("certificate", 80, reaches="the terminal, the rig file, its calibration history and "
                            "the web page"),
    "check_standard": NameRule("check standard name", 64, reaches="the terminal, the result store, its export and "
                               "the web page"),
}


def name_problem(kind: str, text: object) -> str | None:
    """Why ``text`` is not a good name of this kind (``NAMES``), or None."""
    return NAMES[kind].problem(text)


def check_name(kind: str, text: object) -> str:
    """``text`` if it is a good name of this kind, else InvalidInput saying why."""
    problem = name_problem(kind, text)
    if problem is not None:
        raise InvalidInput(problem)
    assert isinstance(text, str)
    return text


def shown(kind: str, text: object) -> str:
    """``text`` as a terminal or a page may show it: itself when it is a good name of this kind, else escaped
    (``repr``: a name stored before the rule held, or by another program, never reaches a terminal raw)."""
    return text if isinstance(text, str) and name_problem(kind, text) is None else ascii(text)


def content_disposition(filename: str) -> str:
    """An attachment's ``Content-Disposition`` for any file name (RFC 6266): a printable-ASCII fallback in
    ``filename`` and the name itself, percent-encoded UTF-8, in ``filename*``."""
    plain = "".join(ch if 32 <= ord(ch) < 127 and ch not in '"\\;' else "_" for ch in filename)
    return f"attachment; filename=\"{plain}\"; filename*=UTF-8''{quote(filename, safe='')}"
