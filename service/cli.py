"""The `moi` command.

Each subcommand lives in its own module under ``service.commands`` with
``HELP`` (one line), ``add_arguments(parser)`` and ``run(args) -> int``.
Bad input (``measurement.errors.InvalidInput`` and its subclasses) gives one
line on stderr and exit status 2; anything else escaping is a bug (exit 1,
with its traceback).
"""

from __future__ import annotations

import argparse
import importlib
import sys
from typing import Sequence

from measurement.errors import InvalidInput
from service.errors import StoreError

#: subcommand → module (in the order `moi --help` lists them)
COMMANDS = {
    "identify": "service.commands.identify",
    "simulate": "service.commands.simulate",
    "calibrate": "service.commands.calibrate",
    "camera-check": "service.commands.camera_check",
    "measure": "service.commands.measure",
    "run": "service.commands.run",
    "results": "service.commands.results",
    "export": "service.commands.export",
    "spc": "service.commands.spc",
    "store": "service.commands.store",
    "modbus-map": "service.commands.modbus_map",
    "demo": "service.commands.demo",
}


def _modules():
    """Every command module, in ``COMMANDS`` order. One that fails to import is a bug and raises:
    `moi` never lists fewer commands than it has. The modules import only what their arguments
    need; the heavy libraries (scipy, OpenCV, pymodbus...) are imported inside ``run``."""
    for name, path in COMMANDS.items():
        yield name, importlib.import_module(path)


class _Version(argparse.Action):
    """``--version``, looking the installed version up only when asked."""

    def __init__(self, option_strings: Sequence[str], dest: str = argparse.SUPPRESS,
                 default: str = argparse.SUPPRESS, help: str | None = None) -> None:
        super().__init__(option_strings, dest=dest, default=default, nargs=0, help=help)

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace, values: object,
                 option_string: str | None = None) -> None:
        from service import __version__
        print(f"moi {__version__}")
        parser.exit()


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="moi", description="Measure the moment of inertia of a part from a free pendulum swing.")
    parser.add_argument("--version", action=_Version, help="show the version and exit")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    for name, module in _modules():
        p = sub.add_parser(name, help=module.HELP, description=module.HELP)
        module.add_arguments(p)
        p.set_defaults(_run=module.run)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args._run(args) or 0)
    except (InvalidInput, StoreError) as exc:  # a damaged or unusable store is the user's file: one line
        print(f"moi {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"moi {args.command}: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # the reader went away (`moi results | head`): stop quietly, as a command killed by SIGPIPE would
        import os
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no second error when Python flushes
        return 128 + 13


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
