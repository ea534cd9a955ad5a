"""Home Assistant MQTT discovery: the retained config messages of the appliance's entities (the result's
sensors, the state, the part, each quality flag, the buttons, the recipe select and the part ID text).
Entity ids are lower case with underscores (Home Assistant's rule); every numeric sensor has its unit."""

from __future__ import annotations

from typing import Any

from measurement import flags as F

from .settings import MqttSettings
from .topics import Topics


def entity_slug(text: str) -> str:
    """``text`` as Home Assistant allows in an entity id: lower case letters, digits and single underscores."""
    out = "".join(c if c.isascii() and c.isalnum() else "_" for c in text.lower())
    return "_".join(part for part in out.split("_") if part) or "x"


class _Entities:
    """The config messages made so far, and what every one of them shares (the device, its availability)."""

    def __init__(self, settings: MqttSettings, topics: Topics, device_id: str, software_version: str) -> None:
        self.dp = settings.discovery_prefix.strip("/")
        self.node = "".join(c if c.isalnum() or c in "_-" else "_" for c in device_id)
        self.slug = entity_slug(device_id)
        device = {"identifiers": [f"moi_{self.node}"], "name": f"moi {device_id}", "manufacturer": "moi",
                  "model": "pendulum inertia appliance", "sw_version": software_version}
        self.common = {"availability_topic": topics.status, "payload_available": "online",
                       "payload_not_available": "offline", "device": device}
        self.origin = {"name": "moi", "sw_version": software_version}
        self.out: list[tuple[str, dict[str, Any]]] = []

    def add(self, domain: str, key: str, topic_key: str | None = None, **cfg: Any) -> None:
        oid = f"moi_{self.slug}_{entity_slug(key)}"
        # object_id is deprecated in favour of default_entity_id; both until Home Assistant drops object_id
        doc = {"unique_id": f"moi_{self.node}_{key}", "object_id": oid, "default_entity_id": f"{domain}.{oid}",
               **cfg, "origin": self.origin, **self.common}
        self.out.append((f"{self.dp}/{domain}/{self.node}/{topic_key or key}/config",
                         {k: v for k, v in doc.items() if v is not None}))


def discovery_messages(settings: MqttSettings, topics: Topics, device_id: str,
                       software_version: str, recipes: tuple[str, ...] = ()) -> list[tuple[str, dict[str, Any]]]:
    """Home Assistant MQTT discovery config messages (topic, config). ``recipes``: the recipe names (a select
    entity offers them, with "none")."""
    entities = _Entities(settings, topics, device_id, software_version)
    _result_sensors(entities, topics)
    _state_and_part(entities, topics)
    _controls(entities, topics, recipes)
    return entities.out


def _result_sensors(entities: _Entities, topics: Topics) -> None:
    # the result sensors read the retained copy of the latest result: known again right after a
    # Home Assistant restart, not "unknown" until the next measurement. Every one has its unit (SI; "1":
    # a ratio), so Home Assistant keeps long-term statistics of it.
    sensors = [
        ("J", "Moment of inertia", "kg·m²", "{{ value_json.J }}"),
        ("J_std", "Moment of inertia uncertainty", "kg·m²", "{{ value_json.J_std }}"),
        ("J_object", "Moment of inertia of the part (J − tare)", "kg·m²", "{{ value_json.J_object }}"),
        ("omega_n", "Natural angular frequency", "rad/s", "{{ value_json.omega_n }}"),
        ("damping_ratio", "Damping ratio", "1", "{{ value_json.damping_ratio }}"),
        ("residual_rms", "Fit residual RMS", "rad", "{{ value_json.residual_rms_after }}"),
    ]
    for key, name, unit, template in sensors:
        entities.add("sensor", key, name=name, state_topic=topics.last_result, value_template=template,
                     state_class="measurement", unit_of_measurement=unit,
                     json_attributes_topic=topics.last_result if key == "J" else None,
                     json_attributes_template=("{{ {'uuid': value_json.uuid, 'seq': value_json.seq, "
                                               "'finished_at': value_json.finished_at, 'flags': value_json.flags} "
                                               "| tojson }}") if key == "J" else None)


def _state_and_part(entities: _Entities, topics: Topics) -> None:
    # text sensors (no unit: they are words)
    entities.add("sensor", "state", name="Sequencer state", state_topic=topics.state,
                 value_template="{{ value_json.state }}")
    # the part: its ID and its verdict (OK / NOK / INVALID once complete, "pending" before, "none" without a recipe)
    for key, name, template in (
            ("part_id", "Part ID", "{{ value_json.part_id or '' }}"),
            ("verdict", "Part verdict", "{{ value_json.verdict or ('pending' if value_json.recipe else 'none') }}")):
        entities.add("sensor", key, name=name, state_topic=topics.last_result, value_template=template)
    for flag in F.FLAG_BITS:
        # "problem" only for the warnings (the condition may move J beyond its u); the others are information
        entities.add("binary_sensor", f"flag_{flag}", flag, name=f"Flag {flag.replace('_', ' ')}",
                     device_class="problem" if F.grade(flag) == F.WARNING else None, state_topic=topics.last_result,
                     value_template="{{ 'ON' if '" + flag + "' in value_json.flags else 'OFF' }}")


def _controls(entities: _Entities, topics: Topics, recipes: tuple[str, ...]) -> None:
    from service.parts.recipes import PART_ID_LENGTH

    entities.add("button", "measure", name="Measure", command_topic=topics.cmd_measure, payload_press="{}")
    entities.add("button", "abort", name="Abort / acknowledge fault", command_topic=topics.cmd_abort,
                 payload_press="{}")
    if recipes:
        entities.add("select", "recipe", name="Recipe", options=["none", *recipes], command_topic=topics.cmd_recipe,
                     command_template="{{ {'recipe': (0 if value == 'none' else value)} | tojson }}",
                     state_topic=topics.recipe, value_template="{{ value_json.name }}")
    entities.add("text", "next_part_id", name="Next part ID", command_topic=topics.cmd_part_id,
                 command_template="{{ {'part_id': value} | tojson }}", state_topic=topics.part_id,
                 value_template="{{ value_json.part_id }}", min=0, max=PART_ID_LENGTH, pattern="[ -~]*")
