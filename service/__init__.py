"""moi service: the daemon and what surrounds the measurement: the command line, the configuration, the devices,
the inputs read from files, recipes and parts, the result store, and the publishers (``service.publish``)."""

from typing import Any


def __getattr__(name: str) -> Any:
    # the installed version, looked up on first use: importlib.metadata is slow to import, and
    # `moi --help` does not need it
    if name == "__version__":
        from importlib.metadata import PackageNotFoundError, version

        try:
            value = version("moi")
        except PackageNotFoundError:  # running from a source tree without installation
            value = "0.0.0+source"
        globals()["__version__"] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
