"""The `moi` command.

Each subcommand lives in its own module under ``service.commands`` with
``add_arguments(parser)`` and ``run(args) -> int``; its one-line help is in ``COMMANDS``.
Bad input (``measurement.errors.InvalidInput`` and its subclasses) gives one
line on stderr and exit status 2; anything else escaping is a bug (exit 1,
with its traceback).
"""

from __future__ import annotations

import argparse
import errno
import importlib
import sys
from typing import Sequence

from measurement.errors import InvalidInput
from service.errors import StartupError, StoreError

#: subcommand → (module, one-line help), in the order `moi --help` lists them. A module is imported
#: only when its command runs (or its own --help is asked): `moi --help` loads no command.
COMMANDS: dict[str, tuple[str, str]] = {
    "identify": ("service.commands.identify",
        "identify J, ω_n and the damping from a trace CSV or a video"),
    "tensor": ("service.commands.tensor",
        "the inertia tensor, principal moments and axes of a part from a plan of swing axes and their traces"),
    "markers": ("service.commands.markers",
        "a trace CSV from two markers tracked on the pendulum, the camera's oblique view measured and removed"),
    "simulate": ("service.commands.simulate",
        "simulate a free swing with chosen effects, noise, quantisation and sample rate"),
    "calibrate": ("service.commands.calibrate",
        "calibrate a torsion rig's stiffness and tare inertia from reference loads"),
    "check-standard": ("service.commands.check_standard",
        "measure a reference artifact of certified J ± U: the normalised error E_n, its history and control chart"),
    "camera-check": ("service.commands.camera_check",
        "find the target in the first frame (annotated PNG) and the share of the first seconds tracked"),
    "measure": ("service.commands.measure",
        "one push-button measurement cycle, on the simulated rig (--sim) or the configured devices (--config), printed"),
    "run": ("service.commands.run",
        "run the appliance daemon: sequencer, result store, MQTT, Modbus server, systemd notify"),
    "results": ("service.commands.results",
        "list the stored measurements, or show one in full"),
    "export": ("service.commands.export",
        "export stored measurements to CSV or JSON, a recipe's parts to AQDEF (Q-DAS DFQ), or one measurement's raw trace"),
    "report": ("service.commands.report",
        "the quality record of one measurement as a PDF (verdict, J ± U, releases, evidence, calibration)"),
    "user": ("service.commands.user",
        "named users of the web page (operator, quality, admin): add, change, remove, list (audited)"),
    "spc": ("service.commands.spc",
        "SPC per recipe: control chart numbers, capability, run rules and a control-chart PNG"),
    "store": ("service.commands.store",
        "check a result store for damage, or salvage what can be read into a new one"),
    "modbus-map": ("service.commands.modbus_map",
        "print the Modbus register map (Markdown, as in docs/modbus.md), check the doc, or read a live appliance"),
    "demo": ("service.commands.demo",
        "the appliance on the simulated rig: one push-button measurement, printed with its Modbus registers (and MQTT)"),
}


def _chosen(argv: Sequence[str]) -> str | None:
    """The subcommand named on the command line: the first word that is not an option (None if none)."""
    word = next((w for w in argv if not w.startswith("-")), None)
    return word if word in COMMANDS else None


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


def build_parser(argv: Sequence[str] | None = None) -> argparse.ArgumentParser:
    """The `moi` parser. Every command is listed; only the one that ``argv`` names (default: the
    process's arguments) has its module imported and its arguments added."""
    parser = argparse.ArgumentParser(
        prog="moi", description="Measure the moment of inertia of a part from a free pendulum swing.")
    parser.add_argument("--version", action=_Version, help="show the version and exit")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True
    chosen = _chosen(sys.argv[1:] if argv is None else argv)
    for name, (path, text) in COMMANDS.items():
        p = sub.add_parser(name, help=text, description=text)
        if name == chosen:
            module = importlib.import_module(path)  # an import error here is a bug: it raises
            module.add_arguments(p)
            p.set_defaults(_run=module.run)
    return parser


#: errors of writing the output that are the place it goes to, not a bug: no space, quota, too large, I/O
_OUTPUT_ERRNOS = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EIO})


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser(argv)
    args = parser.parse_args(argv)
    try:
        status = int(args._run(args) or 0)
        sys.stdout.flush()  # a full disk under stdout is met here, not at the interpreter's exit
        return status
    except (InvalidInput, StoreError, StartupError) as exc:
        # a damaged or unusable store is the user's file, a taken port or state directory the machine's: one line
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
    except OSError as exc:
        if exc.errno not in _OUTPUT_ERRNOS:
            raise
        # the output could not be written (`moi export > /dev/full`, a full disk): one line, as for bad input
        import os
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no second error when Python flushes
        print(f"moi {args.command}: error: cannot write the output: {exc.strerror}", file=sys.stderr)
        return 2


#: commands whose process has nothing left to do once they return (no thread, no file, no child still
#: working): it ends there, its output flushed, instead of tearing the interpreter down, which takes some
#: 0.1 s once scipy and numba are loaded: a fifth of a cold `moi identify`
QUICK_EXIT = frozenset({"identify"})


def console() -> None:
    """The ``moi`` command (and ``python -m service.cli``): ``main`` with the process's arguments, then exit."""
    status = main()
    if _chosen(sys.argv[1:]) in QUICK_EXIT:
        import os

        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(status)
    sys.exit(status)


if __name__ == "__main__":  # pragma: no cover
    console()
