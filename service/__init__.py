"""moi service: the daemon and the user's front (CLI, config, store, MQTT, Modbus)."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("moi")
except PackageNotFoundError:  # running from a source tree without installation
    __version__ = "0.0.0+source"
