"""A ``.phyphox`` file with its data (phyphox's "save experiment state"): XML whose data containers hold
the samples in their ``init`` attribute and whose ``<export>`` sets name the columns."""

from __future__ import annotations

import xml.etree.ElementTree as ET

import numpy as np

from service.errors import InputFileError

from .log import Column, Log
from .registry import Format, Probe, whole_text


def _tag(el: ET.Element) -> str:
    return el.tag.rsplit("}", 1)[-1]


def sniff(probe: Probe) -> bool:
    head = probe.head.lstrip()
    return head.startswith("<") and "<phyphox" in head[:2000]


def _values(text: str | None) -> np.ndarray:
    cells = [c for c in (text or "").replace(";", ",").split(",") if c.strip()]
    try:
        return np.array([float(c) for c in cells])
    except ValueError:
        raise InputFileError(f"a data container's values are not numbers: {cells[:3]!r}") from None


def _events(root: ET.Element) -> tuple[tuple[str, float], ...]:
    """Start and pause events where the file keeps them (elements with an experiment time)."""
    out = []
    for el in root.iter():
        when = el.get("experimentTime") or el.get("experiment-time")
        what = (el.get("type") or el.get("event") or _tag(el)).upper()
        if when is not None and what in ("START", "PAUSE"):
            out.append((what, float(when)))
    return tuple(sorted(out, key=lambda e: e[1]))


def read(probe: Probe) -> Log:
    try:
        root = ET.fromstring(whole_text(probe, ".phyphox file"))
    except ET.ParseError as exc:
        raise InputFileError(f"{str(probe.path)!r} is not valid XML: {exc}") from None
    containers = {(el.text or "").strip(): el.get("init") for el in root.iter() if _tag(el) == "container"}
    for s in (el for el in root.iter() if _tag(el) == "set"):
        cols = [(d.get("name") or "", (d.text or "").strip()) for d in s if _tag(d) == "data"]
        arrays = [_values(containers.get(buffer)) for _, buffer in cols]
        if len(arrays) >= 2 and arrays[0].size >= 30:
            n = min(a.size for a in arrays)
            data = np.column_stack([a[:n] for a in arrays])
            return Log(str(probe.path), "phyphox-xml", tuple(Column.parse(name) for name, _ in cols), data,
                       _events(root), notes=(f"export set {s.get('name')!r}",))
    raise InputFileError(f"{str(probe.path)!r}: a phyphox experiment without recorded data (no export set whose "
                         "containers hold samples); save the experiment's state after recording, or export CSV")


FORMAT = Format(
    "phyphox-xml", "a .phyphox file saved with its data (XML, read by the standard library's parser)",
    "moi identify pendulum.phyphox --rig rig.toml", sniff, read)
