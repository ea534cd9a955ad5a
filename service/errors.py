"""Errors of the service package (CLI, config, store, publishers).

``ConfigError`` and ``InputFileError`` are input errors: the CLI prints one
line and exits 2. ``ServiceError`` subclasses that are not input errors are
runtime faults the daemon turns into its FAULT state.
"""

from measurement.errors import InvalidInput


class ServiceError(Exception):
    """Base of the service package's errors."""


class ConfigError(ServiceError, InvalidInput):
    """A configuration or rig/camera file is unusable; the message says why."""


class InputFileError(ServiceError, InvalidInput):
    """A file named on the command line is missing, unreadable or malformed."""


class StartupError(ServiceError):
    """The daemon cannot start (port in use, unusable state directory, ...); not an input error."""


class AddressInUse(StartupError):
    """A server cannot listen on its port: another program holds it (``port``: the one asked for)."""

    def __init__(self, message: str, port: int) -> None:
        super().__init__(message)
        self.port = port


class ModbusServerError(StartupError):
    """The Modbus server cannot listen on its port or serial line."""


class OpcUaServerError(StartupError):
    """The OPC UA server cannot start: its port, its certificate or its address space cache."""


class StoreError(ServiceError):
    """The result store (SQLite) cannot be opened, read or written."""


class StoreDamaged(StoreError):
    """The result store's file is damaged (SQLite reports corruption, or a stored blob does not decode)."""


class HostStateRefused(ServiceError):
    """A Sparkplug host application's STATE message the edge node does not act on (not the specification's
    JSON, or stamped later than this clock allows); the message says which and what was expected."""
