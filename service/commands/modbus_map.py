"""`moi modbus-map`: print the Modbus register map as Markdown (docs/modbus.md is its output).

`moi modbus-map --check docs/modbus.md` exits 1 when the file differs from the code;
`moi modbus-map --read HOST[:PORT]` reads a running appliance and prints the values.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from typing import Sequence

from measurement import flags as F
from service.publish.modbus import registers as R
from service.sources.files import read_text, write_text_atomic


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--check", metavar="FILE", help="compare FILE with the generated map; exit 2 if it differs")
    p.add_argument("--out", metavar="FILE", help="write the map to FILE instead of stdout")
    p.add_argument("--read", metavar="HOST[:PORT]", help="read the registers of a running appliance (Modbus TCP)")
    p.add_argument("--unit", type=int, default=1, help="unit id for --read (default 1)")
    p.add_argument("--word-order", choices=R.WORD_ORDERS, default="big", help="word order for --read (default big)")


def run(args: argparse.Namespace) -> int:
    if args.read:
        return _read(args)
    text = R.markdown()
    if args.check:
        if read_text(args.check, "register map") != text:
            # a stale document is the user's file, not a bug: exit 2 (exit 1 means a bug)
            print(f"moi modbus-map: {args.check} differs from the register map in the code; "
                  f"regenerate it with `moi modbus-map --out {args.check}`", file=sys.stderr)
            return 2
        print(f"{args.check} matches the register map (version {R.MAP_VERSION})")
        return 0
    if args.out:
        write_text_atomic(args.out, text)
        return 0
    sys.stdout.write(text)
    return 0


def _read(args: argparse.Namespace) -> int:
    from pymodbus.client import ModbusTcpClient

    host, _, port = args.read.partition(":")
    client = ModbusTcpClient(host, port=int(port or 502), timeout=3)
    if not client.connect():
        print(f"moi modbus-map: cannot connect to {args.read}", file=sys.stderr)
        return 3
    try:
        rr = client.read_input_registers(0, count=R.IMAGE_SIZE, device_id=args.unit)
        if rr.isError():
            print(f"moi modbus-map: {args.read} answered {rr}", file=sys.stderr)
            return 3
        print(json.dumps(read_document(rr.registers, args.word_order), indent=2, allow_nan=False))
    finally:
        client.close()
    return 0


def read_document(words: Sequence[int], word_order: str) -> dict:
    """What ``--read`` prints: the registers as read (``raw``: address → word) and their values (``decoded``:
    names and units; NaN as null, so the output is strict JSON; bit fields as lists of names)."""
    values = R.decode_image(words, word_order)
    values = {k: (None if isinstance(v, float) and not math.isfinite(v) else v) for k, v in values.items()}
    values["flags"] = F.flags_from_bits(values["flags"] | values.pop("flags_high") << 16)
    values["state"] = next((k for k, v in R.STATE_CODES.items() if v == values["state"]), values["state"])
    values["status"] = [n for n, b in R.STATUS_BITS.items() if values["status"] >> b & 1]
    values["plc_status"] = [n for n, b in R.PLC_STATUS_BITS.items() if values["plc_status"] >> b & 1]
    values["error_code"] = R.ERROR_CODES.get(values["error_code"], (values["error_code"],))[0]
    values["effects"] = [n for n, b in R.EFFECT_BITS.items() if values["effects"] >> b & 1]
    return {"map_version": R.MAP_VERSION, "word_order": word_order,
            "raw": {str(a): w for a, w in enumerate(words)}, "decoded": values}
