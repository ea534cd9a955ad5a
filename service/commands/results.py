"""`moi results [ID]`: list past measurements, or show one (UUID, UUID prefix or sequence number);
`moi results --part SERIAL`: every measurement of a part, with its releases, verdicts, recipe version and calibration."""

from __future__ import annotations

import argparse
import json
import math
from typing import TYPE_CHECKING, Any, Mapping

from service.errors import InputFileError
from service.parts.outcome import PartOutcome
from service.publish.payload import fmt_time, stored_result

if TYPE_CHECKING:  # pragma: no cover
    from measurement.result import IdentificationResult

from ._common import add_store_arguments, open_store, parse_time


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("id", nargs="?", metavar="ID", help="UUID, UUID prefix or sequence number to show in full")
    add_store_arguments(p)
    p.add_argument("--limit", "-n", type=int, default=20, help="list at most this many, newest first (default 20)")
    p.add_argument("--since", metavar="DATE", help="only measurements finished at or after DATE (ISO 8601, UTC)")
    p.add_argument("--status", choices=("ok", "failed", "aborted"), help="only measurements with this status")
    p.add_argument("--part", metavar="SERIAL", help="every measurement of this part ID: releases, verdicts, recipe "
                                                   "version, calibration")
    p.add_argument("--json", action="store_true", help="print JSON instead of a table/report")


def _num(v, fmt: str) -> str:
    """A number as text, "-" without one (None, or NaN: a number the result JSON wrote null)."""
    return "-" if v is None or (isinstance(v, float) and math.isnan(v)) else format(v, fmt)


def _part(store, serial: str, as_json: bool) -> int:
    rows = list(reversed(store.list(limit=None, part_id=serial, full=True)))  # oldest first
    if not rows:
        raise InputFileError(f"no measurement of part {serial!r} in {store.path}")
    if as_json:
        keys = ("part_id", "recipe", "release", "part", "verdict", "calibration")
        docs = [m.summary() | {k: (m.payload or {}).get(k) for k in keys} for m in rows]
        print(json.dumps(docs, indent=2, ensure_ascii=False))
        return 0
    groups: dict[str, list] = {}
    for m in rows:
        groups.setdefault(m.part_uuid or m.uuid, []).append(m)
    print(f"part {serial}: {len(rows)} measurement(s) in {len(groups)} measuring run(s)")
    for part_uuid, ms in groups.items():
        first = ms[0]
        print(f"\n  part run {part_uuid[:8]}  recipe {first.recipe or '-'} (version {first.recipe_version or '-'})")
        for m in ms:
            o = PartOutcome.from_dict(m.payload)
            cal = o.calibration or {}
            d = o.release.decision if o.release is not None else None
            print(f"    seq {m.seq:>5}  {fmt_time(m.finished_at)} UTC  release {m.release_index or '-'}/"
                  f"{m.releases or '-'}  {m.status:7}  {o.release.quantity if o.release else 'J'} = "
                  f"{_num(d.value if d else None, '.7g')} ± {_num(d.u_c if d else None, '.2g')}  {m.verdict or '-':7}  "
                  f"calibration {cal.get('date', '-')}{' (due)' if cal.get('due') else ''}"
                  + (f"  {'; '.join(d.reasons)}" if d and d.reasons else "")
                  + (f"  error: {m.error}" if m.error else ""))
        last = ms[-1]
        outcome = PartOutcome.from_dict(last.payload)
        part = outcome.part
        if part is not None:
            print(f"    part verdict {last.part_verdict}: {part.quantity} = {_num(part.value, '.7g')} "
                  f"± U {_num(part.U, '.2g')} (k = {(outcome.recipe or {}).get('coverage_factor')}), "
                  f"releases used {[i + 1 for i in part.used]}"
                  + "".join(f"\n      excluded release {e['index'] + 1}: {e['reason']}" for e in part.excluded)
                  + "".join(f"\n      {r}" for r in part.decision.reasons))
        else:
            print(f"    incomplete: {len(ms)} of {first.releases or '?'} releases")
    return 0


def _show_result(r: IdentificationResult, p: Mapping[str, Any]) -> None:
    """One result in words: its fields, and the part keys of its payload's envelope ``p``."""
    print(f"  J             = {_num(r.J, '.7g')} ± {_num(r.J_std, '.2g')} kg·m²")
    if r.J_object is not None:
        print(f"  J_object      = {_num(r.J_object, '.7g')} ± {_num(r.J_object_std, '.2g')} kg·m² (J − tare)")
    print(f"  omega_n       = {_num(r.omega_n, '.7g')} ± {_num(r.omega_n_std, '.2g')} rad/s")
    print(f"  damping ratio = {_num(r.damping_ratio, '.4g')} ± {_num(r.damping_ratio_std, '.2g')}")
    print(f"  effects       : {', '.join(r.effects) or '-'} (added: {', '.join(r.added_effects) or 'none'})")
    print(f"  residual RMS  : {_num(r.baseline.residual_rms, '.3g')} rad declared model → "
          f"{_num(r.residual_rms, '.3g')} rad final; noise floor {_num(r.noise_floor, '.3g')} rad")
    print(f"  flags         : {', '.join(r.flags) or 'none'}")
    o = PartOutcome.from_dict(p)
    if o.recipe:
        rel = o.release
        print(f"  part          : {o.part_id or '-'}, recipe {o.recipe['name']} (version "
              f"{o.recipe['version']}), release {rel.index if rel else None}/{rel.of if rel else None} "
              f"{rel.verdict if rel else None}" + (f", part verdict {o.verdict}" if o.verdict else ""))


def run(args: argparse.Namespace) -> int:
    with open_store(args) as store:
        if args.part:
            return _part(store, args.part, args.json)
        if args.id:
            m = store.get(args.id)
            if m is None:
                raise InputFileError(f"no single measurement matches {args.id!r} in {store.path}")
            if args.json:
                doc = m.summary() | {"payload": m.payload, "rig": m.rig, "config": m.config}
                print(json.dumps(doc, indent=2, ensure_ascii=False))
                return 0
            print(f"measurement {m.uuid}  (seq {m.seq}, {m.status}, triggered by {m.trigger})")
            print(f"  started   {fmt_time(m.started_at)} UTC, finished {fmt_time(m.finished_at)} UTC")
            print(f"  published {fmt_time(m.published_at) + ' UTC' if m.published_at else 'not yet (in the outbox, or no publisher delivers from it)'}")
            print(f"  device {m.device_id}, software {m.software_version}")
            if m.error:
                print(f"  error: {m.error}")
            p = m.payload or {}
            r = stored_result(p)
            if r is not None:
                _show_result(r, p)
            elif p:  # a row of an older result schema: what the store's columns hold
                print(f"  J             = {_num(m.J, '.7g')} ± {_num(m.J_std, '.2g')} kg·m²")
                print(f"  omega_n       = {_num(m.omega_n, '.7g')} rad/s, damping ratio {_num(m.damping_ratio, '.4g')}")
                print(f"  flags         : {', '.join(m.flags) or 'none'}  (a result of an older schema: its columns)")
            return 0
        since = parse_time(args.since) if args.since else None
        rows = store.list(limit=args.limit, since=since, status=args.status, full=True)  # full: J_object
        if args.json:
            print(json.dumps([m.summary() for m in rows], indent=2, ensure_ascii=False))
            return 0
        if not rows:
            print(f"no measurements in {store.path}")
            return 0
        print(f"{'seq':>6}  {'finished (UTC)':19}  {'status':7}  {'trigger':7}  {'J [kg·m²]':>13}  {'±':>8}  "
              f"{'J_object':>13}  {'ω_n [rad/s]':>11}  {'ζ':>9}  {'pub':3}  {'uuid':8}  flags / error")
        for m in rows:
            note = m.error if m.error else ", ".join(m.flags)
            if m.recipe:  # the part: ID, recipe, release i/N and its verdict (the part's on its last release)
                part = (f"{m.part_id or '-'} {m.recipe} {m.release_index or '-'}/{m.releases or '-'} "
                        f"{m.verdict or '-'}" + (f" part {m.part_verdict}" if m.part_verdict else ""))
                note = f"[{part}] {note}".rstrip()
            print(f"{m.seq:>6}  {fmt_time(m.finished_at):19}  {m.status:7}  {m.trigger:7}  {_num(m.J, '13.7g')}  "
                  f"{_num(m.J_std, '8.2g')}  {_num((m.payload or {}).get('J_object'), '13.7g')}  {_num(m.omega_n, '11.6g')}  {_num(m.damping_ratio, '9.3g')}  "
                  f"{'yes' if m.published_at else 'no':3}  {m.uuid[:8]}  {note}")
    return 0
