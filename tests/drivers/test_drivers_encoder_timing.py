"""Late encoder replies: their midpoint timestamp is uncertain, so the sample is dropped and counted.

The rule compares a round trip with the link's short ones (the 10th percentile of the
last 256), not with a typical one; the excess it allows is a fixed share of the
capture's shortest round trip, however busy the host; and it never starves a capture
for longer than that window when the whole link slows down.
"""

import numpy as np
import pytest

from drivers.encoder import EncoderConfig, ModbusEncoder
from drivers.errors import DriverConfigError


def encoder(**kw):
    return ModbusEncoder(EncoderConfig(port="socket://127.0.0.1:9", **kw))


def test_a_reply_well_beyond_the_shortest_round_trips_is_late():
    enc = encoder()
    rng = np.random.default_rng(0)
    typical = 3.5e-3 + np.abs(rng.normal(0, 1e-4, 40))
    assert not any(enc._late(float(r)) for r in typical)
    assert enc._late(6e-3)           # 1.7× the short round trips: the timestamp could be 1.2 ms off
    assert not enc._late(4.5e-3)     # 1.3×: kept (off by at most a quarter of the round trip)
    enc.close()


def test_a_busy_spell_with_most_replies_delayed_is_still_judged_against_the_short_ones():
    # a median would follow the delayed majority up and keep them
    enc = encoder()
    for _ in range(40):
        enc._late(1e-3)
    late = [enc._late(r) for r in [1.8e-3] * 30 + [1e-3] * 5]
    assert all(late[:30]) and not any(late[30:])
    enc.close()


def test_one_exceptionally_fast_reply_does_not_make_the_others_late():
    enc = encoder()
    for _ in range(40):
        enc._late(1e-3)
    enc._late(0.2e-3)
    assert not any(enc._late(1.1e-3) for _ in range(50))
    enc.close()


def test_a_link_that_slows_down_for_good_is_followed_within_the_window():
    enc = encoder()
    for _ in range(300):
        enc._late(1e-3)
    late = [enc._late(3e-3) for _ in range(300)]
    assert late[0] and not late[-1]
    assert sum(late) < 256          # at most one window of samples is lost
    enc.close()


def test_the_allowed_excess_does_not_grow_while_the_host_is_slow():
    # the link's own round trip is 1 ms; a busy host doubles every round trip for a while
    enc = encoder()
    for _ in range(300):
        enc._late(1e-3)
    for _ in range(300):
        enc._late(2e-3)
    assert enc._late(2.7e-3)         # 0.7 ms over the busy reference: more than half the link's 1 ms
    assert not enc._late(2.4e-3)
    enc.close()


def test_first_replies_are_never_judged_and_the_rule_can_be_switched_off():
    enc = encoder()
    assert not any(enc._late(r) for r in (1e-3, 50e-3, 1e-3))
    enc.close()
    off = encoder(late_reply_factor=0)
    for _ in range(40):
        off._late(3.5e-3)
    assert not off._late(1.0)
    off.close()


@pytest.mark.parametrize("bad", [1.0, 0.5, -1, True, "2"])
def test_late_reply_setting_is_validated(bad):
    with pytest.raises(DriverConfigError, match="late_reply_factor"):
        EncoderConfig(port="socket://127.0.0.1:9", late_reply_factor=bad)
