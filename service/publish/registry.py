"""The publishers the appliance knows, in start order: adding one is one subpackage and one line here.

Each entry names the publisher's configuration table, the module of its ``PUBLISHER`` class (the port,
``service.publish.port``) and the module of its settings (``TABLE``: the settings dataclass and the doc and
limits of each key, from which the configuration's table is built). Both are imported by name, when needed:
the configuration reads the settings modules (no pymodbus, paho, aiohttp or asyncua there), the daemon loads
the publishers its configuration enables.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class PublisherEntry:
    """One publisher: its configuration table (``Config.<name>``, None when off), the module whose ``PUBLISHER``
    class serves it (imported only when the table enables it) and the module whose ``TABLE``
    (``service.settings.schema.PublisherTable``) describes the table."""

    name: str
    module: str
    settings: str
    #: reported on the health page (``/api/health``) under its name, null when off
    in_health: bool = True

    def load(self) -> Any:
        """The publisher class (``service.publish.port.Publisher``)."""
        return importlib.import_module(self.module).PUBLISHER

    def table(self) -> Any:
        """Its configuration table (``service.settings.schema.PublisherTable``)."""
        return importlib.import_module(self.settings).TABLE


#: in start order: Modbus first (the PLC sees STARTING while the devices open), the web page once the
#: sequencer exists, MQTT (its outbox sender delivers at once), OPC UA, Sparkplug B
PUBLISHERS: tuple[PublisherEntry, ...] = (
    PublisherEntry("modbus", "service.publish.modbus.server", "service.publish.modbus.settings"),
    PublisherEntry("web", "service.publish.web.server", "service.publish.web.settings", in_health=False),
    PublisherEntry("mqtt", "service.publish.mqtt.client", "service.publish.mqtt.settings"),
    PublisherEntry("opcua", "service.publish.opcua.server", "service.publish.opcua.settings"),
    PublisherEntry("sparkplug", "service.publish.sparkplug.node", "service.publish.sparkplug.settings"),
)
