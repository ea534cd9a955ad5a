"""Late encoder replies: their midpoint timestamp is uncertain, so the sample is dropped and counted."""

import numpy as np
import pytest

from drivers.encoder import EncoderConfig, ModbusEncoder
from drivers.errors import DriverConfigError


def encoder(**kw):
    return ModbusEncoder(EncoderConfig(port="socket://127.0.0.1:9", **kw))


def test_a_reply_far_slower_than_usual_is_late():
    enc = encoder()
    rng = np.random.default_rng(0)
    typical = 3.5e-3 + rng.normal(0, 1e-4, 40)
    assert not any(enc._late(float(r)) for r in typical)
    assert enc._late(12e-3)          # 8.5 ms late: the timestamp could be 4 ms off
    assert not enc._late(3.6e-3)     # ordinary jitter is kept
    enc.close()


def test_first_replies_are_never_judged_and_the_rule_can_be_switched_off():
    enc = encoder()
    assert not any(enc._late(r) for r in (1e-3, 50e-3, 1e-3))
    enc.close()
    off = encoder(late_reply_sigma=0)
    for _ in range(40):
        off._late(3.5e-3)
    assert not off._late(1.0)
    off.close()


def test_late_reply_setting_is_validated():
    with pytest.raises(DriverConfigError, match="late_reply_sigma"):
        EncoderConfig(port="socket://127.0.0.1:9", late_reply_sigma=1.0)
