"""A command-line option that stands for a setting defaults to that setting's own default."""

from __future__ import annotations

from firmware_host import SequencerConfig
from service.cli import build_parser
from service.publish.web.settings import WebSettings
from service.settings.config import SimulationSettings


def test_moi_measure_defaults_are_the_settings_defaults():
    args = build_parser(["measure"]).parse_args(["measure", "--sim"])
    seq, sim = SequencerConfig(), SimulationSettings()
    assert (args.duration, args.pre_trigger, args.decay_threshold) == \
        (seq.capture_duration, seq.pre_trigger, seq.decay_threshold)
    assert (args.inertia, args.theta0, args.bits, args.latency, args.sensor, args.camera_yaw) == \
        (sim.inertia, sim.theta0, sim.bits, sim.latency, sim.sensor, sim.camera_yaw_deg)
    assert (args.drop_rate, args.crc_rate, args.glitch_rate) == (sim.drop_rate, sim.crc_rate, sim.glitch_rate)


def test_moi_demo_serves_on_the_web_settings_port_by_default():
    assert build_parser(["demo"]).parse_args(["demo"]).web_port == WebSettings().port
