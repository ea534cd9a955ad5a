"""One place for an effect: what the service says of the effects is read from the effect classes."""

from __future__ import annotations

from measurement.effects import EFFECTS
from service.commands.simulate import EFFECT_SYNTAX, parse_effects
from service.publish.modbus import registers as R


def test_the_effects_syntax_names_every_effect_by_a_name_it_accepts():
    for name, effect in EFFECTS.items():
        assert f" {name} " in EFFECT_SYNTAX, name
        for kind in effect.rigs:
            given = effect.default_given(kind)
            assert f"{name} {given} [" in EFFECT_SYNTAX or f"or {given} [" in EFFECT_SYNTAX, (name, kind)
            assert given in effect.given_names(kind) or given in effect.extra_units, (name, given)
            assert parse_effects([f"{name}=0.01"], kind) == {name: {given: 0.01}}


def test_every_effect_has_its_own_modbus_bit():
    assert set(R.EFFECT_BITS) == set(EFFECTS), "an effect of the library without a bit, or a bit of no effect"
    bits = list(R.EFFECT_BITS.values())
    assert len(set(bits)) == len(bits) and R.EFFECT_OTHER_BIT not in bits
