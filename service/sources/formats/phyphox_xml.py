"""A ``.phyphox`` file with its data (phyphox's "save experiment state"): the experiment's own XML with
each data container's samples written into its ``init`` attribute (comma-separated), the ``<export>``
sets naming the columns, and an ``<events>`` block of ``<start>`` and ``<pause>`` elements whose
``experimentTime`` (s, the clock stopping while paused) and ``systemTime`` (ms since 1970) mark where the
recording was started and paused. Files saved before the events block existed (phyphox 1.1.8) have none:
the log is then one section."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np

from service.errors import InputFileError

from .log import Column, Log
from .registry import Format, Probe, whole_text

#: the events a saved state records (an event of another name, as a later phyphox may add, is left out)
EVENTS = ("start", "pause")


def _tag(el: ET.Element) -> str:
    return el.tag.rsplit("}", 1)[-1]


def sniff(probe: Probe) -> bool:
    head = probe.head.lstrip()
    return head.startswith("<") and "<phyphox" in head[:2000]


def _values(text: str | None, buffer: str) -> np.ndarray:
    cells = [c.strip() for c in (text or "").split(",") if c.strip()]
    try:
        return np.array([float(c) for c in cells])
    except ValueError:
        raise InputFileError(f"data container {buffer!r}: values that are not numbers ({cells[:3]!r}); expected "
                             "the comma-separated samples phyphox saves") from None


def _events(root: ET.Element, source: str) -> tuple[tuple[str, float], ...]:
    """(START or PAUSE, experiment time in s) of the ``<events>`` block directly under ``<phyphox>``."""
    out = []
    for block in (el for el in root if _tag(el) == "events"):
        for ev in block:
            what = _tag(ev).lower()
            if what not in EVENTS:
                continue
            when = ev.get("experimentTime")
            try:
                out.append((what.upper(), float(when if when is not None else "")))
            except ValueError:
                raise InputFileError(f"{source}: a <{what}> event with experimentTime {when!r}; expected the "
                                     "experiment time in s") from None
    return tuple(out)


def read(probe: Probe) -> Log:
    try:
        root = ET.fromstring(whole_text(probe, ".phyphox file"))
    except ET.ParseError as exc:
        raise InputFileError(f"{str(probe.path)!r} is not valid XML: {exc}") from None
    containers = {(el.text or "").strip(): el.get("init") for block in root if _tag(block) == "data-containers"
                  for el in block if _tag(el) == "container"}
    for s in (el for block in root if _tag(block) == "export" for el in block if _tag(el) == "set"):
        cols = [(d.get("name") or "", (d.text or "").strip()) for d in s if _tag(d) == "data"]
        arrays = [_values(containers.get(buffer), buffer) for _, buffer in cols]
        if len(arrays) >= 2 and arrays[0].size >= 30:
            n = min(a.size for a in arrays)
            data = np.column_stack([a[:n] for a in arrays])
            return Log(str(probe.path), "phyphox-xml", tuple(Column.parse(name) for name, _ in cols), data,
                       _events(root, str(probe.path)), notes=(f"export set {s.get('name')!r}",))
    raise InputFileError(f"{str(probe.path)!r}: a phyphox experiment without recorded data (no export set whose "
                         "containers hold samples); save the experiment's state after recording, or export CSV")


FORMAT = Format(
    "phyphox-xml", "a .phyphox file saved with its data (phyphox's saved experiment state: XML read by the "
                   "standard library's parser; its <events> START/PAUSE split the log)",
    "moi identify 'Gyroscope rotation rate.phyphox' --rig rig.toml", sniff, read)
