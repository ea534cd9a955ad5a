"""The commands and the live status are contracts of the core: one table that the daemon dispatches through and
every surface (Modbus coils and command codes, MQTT topics, the web page) names its commands from."""

from __future__ import annotations

import dataclasses

import pytest

from service.core import vocabulary as V
from service.core.live import LiveStatus
from service.dispatch import Dispatcher
from service.publish.modbus import registers as R
from service.publish.mqtt.topics import Topics


def test_the_daemon_acts_on_every_act_of_the_table_and_on_no_other():
    assert set(Dispatcher._ACTS) | {"part"} == set(V.ACTS)
    assert {c.act for c in V.COMMANDS.values()} == set(V.ACTS)


def test_a_command_with_an_unknown_act_is_refused_by_the_table():
    with pytest.raises(ValueError, match="act 'launch'"):
        V.Command("launch the part", "launch")


def test_the_modbus_coils_and_command_codes_queue_commands_of_the_table():
    for name in R.COILS:
        assert name in V.COMMANDS, name
    for name in R.COMMANDS.values():
        assert R.DAEMON_COMMAND.get(name, name) in V.COMMANDS, name
    # the tensor set's coils stand for the set actions the tensor set takes
    from service.parts.tensor_set import ACTIONS
    assert {V.COMMANDS[n].set_action for n in R.COILS if V.COMMANDS[n].act == "set"} == set(ACTIONS)


def test_the_mqtt_command_topics_are_the_tables():
    topics = Topics("moi", "rig-1")
    assert topics.commands == {f"moi/rig-1/cmd/{c.topic}": name for name, c in V.COMMANDS.items() if c.topic}
    # the topics the client subscribes to and the names the table gives them
    assert topics.commands[topics.cmd_measure] == V.TRIGGER
    assert {topics.cmd_abort, topics.cmd_recipe, topics.cmd_set, topics.cmd_part_id} < set(topics.commands)


def test_a_part_command_changes_the_part_and_a_trigger_may():
    assert V.COMMANDS[V.RECIPE].sets_part and V.COMMANDS[V.PART_ID].sets_part and V.COMMANDS[V.TRIGGER].sets_part
    assert not V.COMMANDS[V.ABORT].sets_part and not V.COMMANDS[V.SET].sets_part


def test_the_live_status_is_encoded_by_the_modbus_codec_not_by_itself():
    live = LiveStatus(state="CAPTURING", busy=True, outbox_pending=2)
    assert not hasattr(live, "status_bits")
    bits = R.status_bits(live, result_valid=True, verdict="NOK")
    assert bits == sum(1 << R.STATUS_BITS[n] for n in ("busy", "result_valid", "outbox_pending", "part_nok"))
    assert {f.name for f in dataclasses.fields(LiveStatus)} >= {"state", "busy", "fault", "calibration_due"}


def test_plc_status_bits_are_one_table_with_their_meaning():
    assert {name: bit for name, (bit, _) in R.PLC_STATUS.items()} == R.PLC_STATUS_BITS
    doc = R.markdown()
    for name, (bit, meaning) in R.PLC_STATUS.items():
        assert f"| {bit} | `{name}` | {meaning} |" in doc
