"""Commands that do not identify start without the heavy libraries (the appliance is a Raspberry Pi): the
fit's (scipy), the pictures' (opencv, PyAV, matplotlib), the kernels' compiler (numba) and the publishers'
(pymodbus, paho-mqtt, aiohttp, asyncua)."""

import subprocess
import sys

import pytest

from service.cli import COMMANDS, build_parser

HEAVY = ("scipy", "cv2", "matplotlib", "av", "numba", "pymodbus", "paho", "aiohttp", "asyncua")

PROBE = """
import sys
from service.cli import main
try:
    main(sys.argv[1:])
except SystemExit:
    pass
sys.stderr.write("LOADED:" + " ".join(m for m in {heavy!r} if m in sys.modules) + "\\n")
"""


@pytest.mark.parametrize("argv", [["--help"], ["identify", "--help"], ["results", "--help"], ["export", "--help"],
                                  ["modbus-map"]], ids=lambda a: " ".join(a))
def test_commands_that_do_not_identify_import_no_heavy_library(argv):
    err = subprocess.run([sys.executable, "-c", PROBE.format(heavy=HEAVY), *argv], capture_output=True, text=True,
                         timeout=120, check=True).stderr
    loaded = next(line for line in err.splitlines() if line.startswith("LOADED:"))[len("LOADED:"):]
    assert loaded == "", f"moi {' '.join(argv)} imported {loaded}"


def test_every_command_is_listed():
    # a command module that fails to import raises instead of silently vanishing from `moi --help`
    parser = build_parser(["--help"])
    sub = next(a for a in parser._actions if a.dest == "command")
    assert sub.choices is not None and list(sub.choices) == list(COMMANDS)


@pytest.mark.parametrize("name", list(COMMANDS))
def test_every_command_module_imports_and_builds_its_arguments(name):
    # `moi --help` imports no command module, so each is imported here as its own run would
    parser = build_parser([name, "--help"])
    sub = next(a for a in parser._actions if a.dest == "command")
    assert isinstance(sub.choices, dict) and callable(sub.choices[name].get_default("_run"))
