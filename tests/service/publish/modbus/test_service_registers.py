"""The register map: encoding, the generated documentation, flags."""

from __future__ import annotations

import math
import struct
import uuid
from pathlib import Path

import numpy as np
import pytest

from measurement import flags as F
from service.commands import modbus_map
from service.publish.modbus import registers as R

REPO = Path(__file__).resolve().parents[4]


def payload(seq: int = 5, **over) -> dict:
    p = {
        "uuid": str(uuid.UUID(int=0x0123456789ABCDEF0011223344556677)), "seq": seq, "timestamp": 1_700_000_000.75,
        "J": 0.012500019744038582, "J_std": 6.2e-08, "omega_n": 5.404438495635986, "omega_n_std": 1.3e-05,
        "damping_ratio": 0.0019768, "damping_ratio_std": 2.58e-06, "residual_rms_after": 1.065e-4,
        "residual_rms_before": 2.5e-4, "noise_floor": 1.08e-4, "J_object": None, "J_U": 3.1e-5, "J_object_U": None,
        "flags": ["outliers_removed", "some_future_flag"], "effects": ["viscous", "coulomb"],
    }
    p.update(over)
    return p


@pytest.mark.parametrize("order", R.WORD_ORDERS)
def test_snapshot_round_trip_is_exact_to_float32(order):
    p = payload()
    words = R.encode_snapshot(p, order)
    assert len(words) == R.SNAPSHOT_END - R.SNAPSHOT_START
    d = R.decode_image(words, order, start=R.SNAPSHOT_START)
    for reg, key in (("J", "J"), ("J_std", "J_std"), ("omega_n", "omega_n"), ("damping_ratio", "damping_ratio"),
                     ("residual_rms", "residual_rms_after"), ("residual_rms_before", "residual_rms_before"),
                     ("J_U", "J_U")):
        assert d[reg] == float(np.float32(p[key])), reg
    assert math.isnan(d["J_object"]) and math.isnan(d["J_object_U"])  # None → NaN
    assert d["seq"] == d["seq_end"] == 5
    assert d["timestamp"] == 1_700_000_000
    assert d["uuid"] == p["uuid"]
    assert F.flags_from_bits(d["flags"]) == ["outliers_removed", "other"]
    assert d["effects"] == 0b11


def test_word_order_swaps_the_two_registers_of_a_float():
    big = R.encode_value("float32", 1.5, "big")
    little = R.encode_value("float32", 1.5, "little")
    assert big == list(struct.unpack(">HH", struct.pack(">f", 1.5)))
    assert little == big[::-1]
    assert R.encode_value("uint32", 0x12345678, "big") == [0x1234, 0x5678]
    assert R.encode_value("uint32", 0x12345678, "little") == [0x5678, 0x1234]


def test_sequence_number_wraps_past_zero():
    assert R.modbus_seq(0) == 0
    assert R.modbus_seq(1) == 1
    assert R.modbus_seq(65535) == 65535
    assert R.modbus_seq(65536) == 1  # 0 stays reserved for "no result"


def test_every_known_flag_has_its_own_bit():
    assert len(set(F.FLAG_BITS.values())) == len(F.FLAG_BITS)
    assert F.FLAG_OTHER_BIT not in F.FLAG_BITS.values()
    for name, bit in F.FLAG_BITS.items():
        assert F.flag_bits([name]) == 1 << bit
    assert F.flag_bits(["not_a_flag"]) == 1 << F.FLAG_OTHER_BIT


def test_the_whole_image_fits_one_request_and_registers_do_not_overlap():
    assert R.IMAGE_SIZE <= 125
    seen: set[int] = set()
    for r in R.REGISTERS:
        span = set(range(r.address, r.address + r.count))
        assert not (span & seen), r.name
        seen |= span
    assert R.BY_NAME["seq"].address == R.SNAPSHOT_START
    assert R.BY_NAME["seq_end"].address == R.SNAPSHOT_END - 1


def test_no_result_yet_reads_as_seq_zero_and_nan():
    d = R.decode_image(R.encode_snapshot(None), start=R.SNAPSHOT_START)
    assert d["seq"] == 0 and d["seq_end"] == 0 and d["uuid"] is None
    assert math.isnan(d["J"])


def test_committed_register_doc_matches_the_code():
    committed = (REPO / "docs" / "modbus.md").read_text(encoding="utf-8")
    assert committed == R.markdown(), "docs/modbus.md is stale: run `moi modbus-map > docs/modbus.md`"


def test_modbus_map_command_prints_the_doc(capsys):
    import argparse

    p = argparse.ArgumentParser()
    modbus_map.add_arguments(p)
    assert modbus_map.run(p.parse_args([])) == 0
    assert capsys.readouterr().out == R.markdown()
