"""No import circles: no module of the four packages imports, at any depth, a module that imports it back.

Every import counts, at the top of a module, inside a function and under ``TYPE_CHECKING``:
a circle that only typing or a function-level import hides is still two modules that cannot
be understood (or moved) one without the other. ``from package import submodule`` is an
import of the submodule, not of the package's ``__init__``.
"""

from __future__ import annotations

import ast
import functools
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("measurement", "drivers", "firmware_host", "service")


def modules() -> dict[str, tuple[Path, bool]]:
    found = {}
    for pkg in PACKAGES:
        for path in (ROOT / pkg).rglob("*.py"):
            parts = list(path.relative_to(ROOT).with_suffix("").parts)
            is_package = parts[-1] == "__init__"
            found[".".join(parts[:-1] if is_package else parts)] = (path, is_package)
    return found


@functools.lru_cache(maxsize=1)  # parsed once for the tests of this file; none changes it
def import_graph() -> dict[str, set[str]]:
    mods = modules()
    graph: dict[str, set[str]] = {m: set() for m in mods}
    for name, (path, is_package) in mods.items():
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base_parts = name.split(".") if is_package else name.split(".")[:-1]
                    base_parts = base_parts[:len(base_parts) - (node.level - 1)]
                    base = ".".join(base_parts + ([node.module] if node.module else []))
                else:
                    base = node.module or ""
                subs = [f"{base}.{a.name}" for a in node.names if f"{base}.{a.name}" in mods]
                targets = subs if len(subs) == len(node.names) else [base, *subs]
            else:
                continue
            graph[name].update(t for t in targets if t in mods and t != name)
    return graph


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                out.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


def test_the_walker_sees_a_circle():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert circles(graph) == [["a", "b", "c"]]


def test_the_import_graph_covers_the_packages():
    graph = import_graph()
    assert len(graph) > 80
    assert "service.publish.port" in graph["service.daemon"]
    assert "measurement.flags" in graph["measurement.identification.flags"]


def test_no_import_circles():
    assert circles(import_graph()) == []


def test_the_science_layer_imports_no_service_driver_or_host_module():
    graph = import_graph()
    upward = {(m, t) for m, ts in graph.items() if m.startswith("measurement") for t in ts
              if not t.startswith("measurement")}
    assert upward == set()


# --- the layer matrix --------------------------------------------------------------------------------------------

#: the rooms of the four packages: a module's room is its package's name, ``service``'s subpackage (``service.X``),
#: or, for a publisher (a subpackage of ``service/publish/``), ``publish.<name>``; ``service`` alone is the
#: package's ``__init__`` (its version)
PUBLISHERS = tuple(p.name for p in (ROOT / "service" / "publish").iterdir() if (p / "__init__.py").exists())

#: what a publisher may import unless its row says otherwise: a new publisher needs no row here
PUBLISHER_ROW = {"core", "drivers", "errors", "measurement", "parts", "persistence", "publish", "settings"}

#: room → the rooms it may import. The whole matrix: an import into a room not listed fails, so a new dependency
#: is a decision written here, and the list only shrinks. Read it as the layers, bottom up: the science
#: (``measurement``), the drivers and the host's sequencer; the floor of the service (``errors``, ``states``,
#: ``core``: the live status and the command vocabulary, ``notify``, ``names``; ``settings``: the settings toolkit
#: every settings module imports, the validated configuration's types, the demo defaults, the sensors' registry);
#: what the appliance is made of (``devices``, ``sources``, ``parts``, ``persistence``); the publishers; the
#: configuration's assembler (``config``: every table from the registries, `moi run --check`), which only the
#: daemon and the command line import; the daemon; the command line (``commands``), which only ``cli`` imports.
LAYERS: dict[str, set[str]] = {
    "measurement": set(),
    "drivers": {"measurement"},
    "firmware_host": {"drivers", "measurement"},
    "service": set(),
    "errors": {"measurement"},
    "states": set(),
    "notify": set(),
    "core": set(),
    # the rule for every name that reaches a topic, a header, a file name, an export, a terminal or a page (the
    # calibration history's and the commands' names too); the log's repeat filter;
    # the capture's contention watch
    "names": {"measurement"},
    "logs": set(),
    "contention": set(),
    # the sequencer's settings are a table of the file (``SequencerConfig``)
    "settings": {"errors", "firmware_host", "measurement"},
    "sources": {"drivers", "errors", "measurement", "names"},
    # the camera sensor reads its camera file (``sources.camera``)
    "devices": {"drivers", "errors", "firmware_host", "measurement", "settings", "sources"},
    "parts": {"errors", "measurement", "names", "settings", "sources"},
    # a stored run's operator read from its trigger, by the commands' vocabulary (the migration of older stores)
    "persistence": {"core", "errors", "sources"},
    # the port, payload, quality words, report, plot and export: what every publisher shares
    "publish": {"core", "devices", "errors", "firmware_host", "measurement", "notify", "parts", "persistence",
                "service", "settings", "states"},
    "publish.modbus": {"core", "drivers", "errors", "measurement", "parts", "persistence", "publish", "settings",
                       "states"},
    # the Sparkplug node throttles the log lines a broker client can make it repeat (``logs.Throttle``), as MQTT does
    "publish.mqtt": {"core", "errors", "logs", "measurement", "parts", "persistence", "publish", "settings"},
    "publish.sparkplug": {"errors", "logs", "parts", "persistence", "publish", "settings"},
    "publish.opcua": {"drivers", "errors", "names", "parts", "persistence", "publish", "settings", "states"},
    "publish.web": {"core", "drivers", "errors", "firmware_host", "measurement", "names", "parts", "persistence",
                    "publish", "service", "settings", "sources", "states"},
    # the assembler: the appliance's tables, each sensor's (``settings.sensor_registry``) and each publisher's
    # (``publish.registry``), the rig and camera files, the recipes
    "config": {"drivers", "errors", "firmware_host", "measurement", "names", "parts", "publish", "settings",
               "sources"},
    # the commands the daemon's main loop acts on
    "dispatch": {"core", "firmware_host", "measurement", "parts", "publish", "settings"},
    # the daemon's results: each run stored once, judged for its part, then handed to the publishers
    "recording": {"core", "errors", "firmware_host", "measurement", "parts", "publish", "service", "settings"},
    # ``sources``: the rig's repeat releases in the store (``sources.repeats``), read into its own identifications
    "daemon": {"config", "contention", "core", "devices", "dispatch", "errors", "firmware_host", "measurement",
               "notify", "parts", "persistence", "publish", "recording", "service", "settings", "sources"},
    # ``service``: the installed version (the calibration history names the software that wrote a line)
    "commands": {"config", "core", "daemon", "devices", "drivers", "errors", "firmware_host", "logs", "measurement",
                 "names", "parts", "persistence", "publish", "publish.modbus", "publish.web", "service", "settings",
                 "sources"},
    "cli": {"errors", "measurement", "service"},
}


def room(module: str) -> str:
    parts = module.split(".")
    if parts[0] != "service" or len(parts) == 1:
        return parts[0]
    if parts[1] == "publish" and len(parts) > 2 and parts[2] in PUBLISHERS:
        return f"publish.{parts[2]}"
    return parts[1]


def room_imports(graph: dict[str, set[str]]) -> dict[tuple[str, str], list[str]]:
    """(importing room, imported room) → the imports that make it (modules of one room among themselves left out)."""
    edges: dict[tuple[str, str], list[str]] = {}
    for m, targets in graph.items():
        for t in targets:
            if room(m) != room(t):
                edges.setdefault((room(m), room(t)), []).append(f"{m} -> {t}")
    return edges


def allowed(r: str) -> set[str]:
    return LAYERS.get(r, PUBLISHER_ROW if r.startswith("publish.") else set())


def test_every_room_has_a_row_of_the_matrix():
    rooms = {room(m) for m in import_graph()}
    assert rooms - set(LAYERS) <= {f"publish.{p}" for p in PUBLISHERS}, "a room without a row"
    assert all(deps <= rooms for deps in LAYERS.values())
    assert {"publish.modbus", "publish.mqtt", "publish.opcua", "publish.web"} <= rooms


def test_the_layer_matrix_holds():
    outside = {edge: imports for edge, imports in room_imports(import_graph()).items() if edge[1] not in allowed(edge[0])}
    assert outside == {}, "imports the layer matrix does not allow (LAYERS): " + repr(outside)


def test_the_walker_sees_an_import_the_matrix_refuses():
    graph = {"service.publish.web.views": {"service.commands.export"}, "service.commands.export": set()}
    edges = room_imports(graph)
    assert ("publish.web", "commands") in edges and "commands" not in allowed("publish.web")
    assert "commands" not in allowed("publish.fieldbus") and "daemon" not in allowed("publish.fieldbus")


def test_only_the_command_line_imports_the_commands_and_no_publisher_imports_the_daemon():
    for r, deps in LAYERS.items():
        assert "commands" not in deps or r == "cli", r
        assert "daemon" not in deps or r == "commands", r


def test_the_core_imports_nothing_of_the_service():
    assert LAYERS["core"] == set() and LAYERS["states"] == set()


def test_the_architecture_map_names_every_room():
    text = (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")
    for r in LAYERS:
        name = {"service": "service/", "cli": "service/cli.py"}.get(r, r.replace("publish.", "") + "/"
                                                                     if r.startswith("publish.") else None)
        if name is None:
            name = f"service/{r}" if (ROOT / "service" / r).exists() or (ROOT / "service" / f"{r}.py").exists() \
                else f"{r}/"
        assert name in text, f"docs/architecture.md does not name the room {r} ({name})"


# --- one order: no two rooms import each other -----------------------------------------------------------------

def two_way_pairs(graph: dict[str, set[str]]) -> set[tuple[str, str]]:
    """The pairs of rooms (sorted) each of which imports the other."""
    edges = room_imports(graph)
    return {(min(a, b), max(a, b)) for a, b in edges if (b, a) in edges}


def test_the_walker_sees_two_rooms_importing_each_other():
    graph = {"service.config.appliance": {"service.parts.recipes"}, "service.parts.recipes": {"service.config.schema"},
             "service.config.schema": set()}
    assert two_way_pairs(graph) == {("config", "parts")}


def test_no_two_rooms_import_each_other():
    """The rooms stand in one order: a room imports only rooms below it, so either can be read (or moved) knowing
    what it stands on. The pairs are measured at the rooms of the layer matrix (``room``)."""
    pairs = two_way_pairs(import_graph())
    assert pairs == set(), f"rooms importing each other: {sorted(pairs)}"
