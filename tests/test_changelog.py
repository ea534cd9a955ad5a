"""A wire-contract version bump comes with a CHANGELOG entry, and the package version moves with it."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

from measurement.result import SCHEMA_VERSION as RESULT_SCHEMA
from service.publish.modbus.registers import MAP_VERSION
from service.publish.payload import PAYLOAD_SCHEMA

ROOT = Path(__file__).resolve().parents[1]


def newest_release(text: str) -> tuple[str, str]:
    """(version, its text) of the first ``## X.Y.Z`` section."""
    m = re.search(r"^## (\d+\.\d+\.\d+)\s*$(.*?)(?=^## |\Z)", text, flags=re.M | re.S)
    assert m is not None, "CHANGELOG.md has no '## X.Y.Z' release"
    return m.group(1), m.group(2)


def contract_versions(section: str) -> dict[str, int]:
    wire = re.search(r"^### Wire contracts\s*$(.*?)(?=^### |\Z)", section, flags=re.M | re.S)
    assert wire is not None, "the release has no '### Wire contracts' section"
    found = {}
    for name, pattern in (("modbus", r"Modbus map version (\d+)"), ("payload", r"MQTT payload schema (\d+)"),
                          ("result", r"result JSON schema (\d+)")):
        m = re.search(pattern, wire.group(1))
        assert m is not None, f"the wire-contract section does not give the {name} version ({pattern})"
        found[name] = int(m.group(1))
    return found


def test_the_newest_release_ships_the_contract_versions_of_the_code():
    version, section = newest_release((ROOT / "CHANGELOG.md").read_text(encoding="utf-8"))
    assert contract_versions(section) == {"modbus": MAP_VERSION, "payload": PAYLOAD_SCHEMA, "result": RESULT_SCHEMA}, (
        "a contract version changed in the code: add a release to CHANGELOG.md saying what changed, "
        "and bump the version in pyproject.toml")


def test_the_package_version_is_the_newest_release():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
    version, _ = newest_release((ROOT / "CHANGELOG.md").read_text(encoding="utf-8"))
    assert project["version"] == version


def test_the_check_catches_a_bump_without_an_entry():
    text = (ROOT / "CHANGELOG.md").read_text(encoding="utf-8")
    _, section = newest_release(text)
    assert contract_versions(section)["modbus"] != MAP_VERSION + 1
    assert contract_versions(section.replace(f"Modbus map version {MAP_VERSION}",
                                             f"Modbus map version {MAP_VERSION - 1}"))["modbus"] != MAP_VERSION
