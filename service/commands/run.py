"""`moi run --config appliance.toml [--sim]`: the appliance daemon (what systemd starts)."""

from __future__ import annotations

import argparse
import logging
import signal
import sys

from service.errors import StartupError, StoreError


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--config", "-c", metavar="appliance.toml",
                   help="configuration file (default: all defaults, simulated rig, MQTT off)")
    p.add_argument("--sim", action="store_true",
                   help="run on the simulated rig even when [hardware] is configured (default without [hardware])")
    p.add_argument("--state-dir", metavar="DIR", help="result store directory (overrides [device] state_dir)")
    p.add_argument("--check", action="store_true",
                   help="validate the configuration and what it names (pins, files, GPIO backend, serial port or "
                        "camera, ports), print a summary and exit (2 if anything is wrong)")
    p.add_argument("--json", action="store_true", help="with --check: print the configuration and the checks as JSON")
    p.add_argument("--log-level", choices=("debug", "info", "warning", "error"), help="overrides [device] log_level")
    p.add_argument("--config-reference", action="store_true",
                   help="print every table and key of the configuration file (Markdown) and exit")
    p.add_argument("--payload-reference", action="store_true",
                   help="print the keys of the published result's envelope (Markdown) and exit")


def setup_logging(level: str) -> None:
    # journald adds its own timestamps; the level and the logger name are what helps there
    logging.basicConfig(level=getattr(logging, level.upper()), stream=sys.stderr,
                        format="%(levelname)s %(name)s: %(message)s", force=True)
    from service.logs import install

    install(getattr(logging, level.upper()))
    if level != "debug":
        # pymodbus logs every refused request (e.g. a PLC writing a read-only register) as an error
        logging.getLogger("pymodbus").setLevel(logging.CRITICAL)


def run(args: argparse.Namespace) -> int:
    if args.config_reference:
        from service.config.appliance import reference_markdown
        sys.stdout.write(reference_markdown())
        return 0
    if args.payload_reference:
        from service.publish.payload import envelope_markdown
        sys.stdout.write(envelope_markdown())
        return 0
    from service.config.appliance import load_config  # the drivers' and servers' settings: not for `moi --help`

    config = load_config(args.config, sim=args.sim, state_dir=args.state_dir)
    from service.config.check import check_config, pin_problems
    from service.errors import ConfigError

    if args.check:
        import json
        checks = check_config(config)
        problems = [c for c in checks if not c.ok]
        if args.json:
            print(json.dumps(config.to_dict() | {"checks": [c.__dict__ for c in checks]}, indent=2, default=str))
        else:
            print("\n".join(c.line() for c in checks))
        if problems:
            raise ConfigError(f"{len(problems)} problem(s): " + "; ".join(f"{c.what}: {c.detail}" for c in problems))
        return 0
    if pin_problems(config):  # gpiozero would fail with a traceback when building the devices
        raise ConfigError("; ".join(pin_problems(config)))
    setup_logging(args.log_level or config.log_level)
    from service.daemon import Appliance

    app = Appliance(config)

    def on_signal(signum, frame):  # a signal handler's signature
        logging.getLogger("moi.daemon").info("signal %s: stopping", signal.Signals(signum).name)
        app.request_stop()

    previous = {s: signal.signal(s, on_signal) for s in (signal.SIGTERM, signal.SIGINT)}
    try:
        try:
            app.start()
        except (StartupError, StoreError) as exc:
            print(f"moi run: error: {exc}", file=sys.stderr)
            return 3
        return app.run()
    finally:
        for s, h in previous.items():
            signal.signal(s, h)
