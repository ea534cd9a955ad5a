"""The MQTT topics of one appliance, under ``<prefix>/<device_id>/`` (what each carries: ``mqtt.client``)."""

from __future__ import annotations

from service.core import vocabulary as V


class Topics:
    def __init__(self, prefix: str, device_id: str) -> None:
        base = f"{prefix.strip('/')}/{device_id}" if prefix.strip("/") else device_id
        self.base = base
        self.result = f"{base}/result"
        self.last_result = f"{base}/result/last"  # retained copy of the latest delivered result
        self.status = f"{base}/status"
        self.state = f"{base}/state"
        self.cmd_measure = f"{base}/cmd/measure"
        self.cmd_abort = f"{base}/cmd/abort"
        self.cmd_recipe = f"{base}/cmd/recipe"
        self.cmd_set = f"{base}/cmd/set"  # a tensor set: {"action": "redo" | "skip" | "abort", "orientation": name}
        self.cmd_part_id = f"{base}/cmd/part_id"
        #: command topic → the daemon's command (``service.core.vocabulary``)
        self.commands = {f"{base}/cmd/{topic}": name for topic, name in V.BY_TOPIC.items()}
        self.reply = f"{base}/reply"      # commands' outcomes (unless an MQTT 5 response topic was given)
        self.recipe = f"{base}/recipe"    # retained: the active recipe {"name", "number"} (name "none": none)
        self.part_id = f"{base}/part_id"  # retained: the next part's ID {"part_id"}
        self.set_state = f"{base}/set"    # retained: the tensor set's progress (the orientation to mount next)
        self.tensor = f"{base}/tensor"    # retained: the latest tensor set's record with its tensor

    def spc(self, recipe: str) -> str:
        """The retained SPC summary topic of a recipe."""
        return f"{self.base}/spc/{recipe}"

    def for_kind(self, kind: str) -> str:
        if kind == "result":
            return self.result
        raise ValueError(f"unknown outbox kind {kind!r}")
