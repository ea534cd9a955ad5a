"""`moi simulate --rig RIG.toml --inertia J --effects ... --out trace.csv`: a synthetic trace."""

from __future__ import annotations

import argparse
import math

from measurement.effect_base import Effect
from measurement.effects import EFFECTS
from measurement.errors import InvalidInput, UnknownEffectError
from service.sources.files import read_rig, write_text_atomic


def _given_unit(effect: type[Effect], given: str) -> str:
    """The unit of a value given by the name ``given`` (a parameter, its physical quantity, or another)."""
    for p in effect.parameters:
        if given == p.physical:
            return p.physical_unit or ""
        if given == p.name:
            return p.unit
    return effect.extra_units.get(given, "")


def _value_syntax(name: str, effect: type[Effect]) -> str:
    """What ``NAME=VALUE`` gives for one effect: its first parameter by the name and unit it is given in, per
    rig kind where they differ."""
    first, *others = effect.rigs
    given = effect.default_given(first)
    text = f"{name} {given} [{_given_unit(effect, given)}]"
    for kind in others:
        g = effect.default_given(kind)
        if g != given:
            text += f" or {g} [{_given_unit(effect, g)}] on a {kind} rig"
    return text


#: the help of --effects, written from the effect classes (every effect of the library, its value's name and unit)
EFFECT_SYNTAX = (
    "effects as NAME=VALUE (the effect's physical parameter: "
    + ", ".join(_value_syntax(name, effect) for name, effect in EFFECTS.items())
    + ") or NAME:PARAM=VALUE, e.g. viscous=2e-4 coulomb:Tc=1e-4"
)


def parse_effects(tokens: list[str], rig_kind: str) -> dict[str, dict[str, float]]:
    out: dict[str, dict[str, float]] = {}
    for raw in tokens:
        for token in filter(None, (s.strip() for s in raw.split(","))):
            if "=" not in token:
                raise InvalidInput(f"effect {token!r}: expected NAME=VALUE or NAME:PARAM=VALUE")
            key, value = token.split("=", 1)
            name, _, param = key.partition(":")
            if name not in EFFECTS:
                raise UnknownEffectError(f"unknown effect {name!r}; expected one of {', '.join(EFFECTS)}")
            try:
                v = float(value)
            except ValueError:
                raise InvalidInput(f"effect {token!r}: {value!r} is not a number") from None
            if not math.isfinite(v):
                raise InvalidInput(f"effect {token!r}: value must be finite")
            if not param:
                param = EFFECTS[name].default_given(rig_kind)
            out.setdefault(name, {})[param] = v
    return out


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--rig", required=True, metavar="RIG.toml", help="rig file (its k or m, S turn J into ω_n)")
    p.add_argument("--inertia", "-J", type=float, required=True, metavar="KG_M2", help="true J about the pivot, kg·m²")
    p.add_argument("--effects", nargs="*", default=[], metavar="EFFECT", help=EFFECT_SYNTAX)
    p.add_argument("--theta0", type=float, default=0.2, metavar="RAD", help="release angle, rad (default 0.2)")
    p.add_argument("--duration", type=float, default=30.0, metavar="S", help="record after the release, s (default 30)")
    p.add_argument("--rate", type=float, default=200.0, metavar="HZ", help="sample rate, Hz (default 200)")
    p.add_argument("--noise", type=float, default=0.0, metavar="RAD", help="white angle noise σ, rad (default 0)")
    p.add_argument("--bits", type=int, default=None, help="encoder resolution in bits per turn (quantisation)")
    p.add_argument("--jitter", type=float, default=0.0, help="timestamp jitter σ as a fraction of the sample interval")
    p.add_argument("--offset", type=float, default=0.0, metavar="RAD", help="sensor zero offset, rad")
    p.add_argument("--pre-trigger", type=float, default=0.0, metavar="S", help="held at theta0 this long before the release, s")
    p.add_argument("--seed", type=int, default=None, help="random seed (reproducible noise)")
    p.add_argument("--out", required=True, metavar="trace.csv", help="output CSV (t in s, angle in rad)")


def run(args: argparse.Namespace) -> int:
    from measurement import Pendulum, simulate_trace  # scipy: only when simulating

    rig = read_rig(args.rig)
    effects = parse_effects(args.effects, rig.kind)
    pendulum = Pendulum(rig, args.inertia, effects)
    trace = simulate_trace(
        pendulum, theta0=args.theta0, duration=args.duration, rate=args.rate, offset=args.offset,
        noise_std=args.noise, quantisation_bits=args.bits, jitter=args.jitter, pre_trigger=args.pre_trigger,
        seed=args.seed,
    )
    desc = ", ".join(f"{k}({', '.join(f'{p}={v:g}' for p, v in ps.items())})" for k, ps in effects.items()) or "no damping"
    comment = (f"moi simulate: {rig.kind} rig, J={args.inertia:g} kg·m², omega_n={pendulum.omega_n:.6g} rad/s, {desc}; "
               f"theta0={args.theta0:g} rad, rate={args.rate:g} Hz, noise={args.noise:g} rad, bits={args.bits}, seed={args.seed}")
    write_text_atomic(args.out, trace.to_csv(comment))
    print(f"wrote {len(trace)} samples ({trace.duration:.3f} s) to {args.out}")
    return 0
