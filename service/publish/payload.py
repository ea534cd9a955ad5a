"""The published result: one dict, from which the MQTT JSON and the Modbus registers are both made.

``result_payload`` takes ``IdentificationResult.to_dict()`` unchanged and adds
an envelope (uuid, sequence number, device, trigger, timestamps, software
version) plus the two residual RMS values under explicit before/after names.
The result store keeps this exact dict; the outbox sends it as JSON; the
Modbus image is encoded from it (``service.publish.modbus.registers.encode_snapshot``).
A reader of a stored or received payload reads its result typed (``stored_result``), once, where the row is
loaded, and its fields from there; so is its part outcome (``service.parts.outcome.PartOutcome.from_dict``).
"""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Any, Mapping

from measurement.errors import ResultSchemaError
from measurement.flags import flag_bits
from measurement.result import IdentificationResult
from service.parts.outcome import PartOutcome

#: the version of the published envelope and topics; what each version changed is in CHANGELOG.md
PAYLOAD_SCHEMA = 6

#: keys the envelope adds on top of the result's own keys
ENVELOPE_KEYS = (
    "payload_schema", "uuid", "seq", "device_id", "software_version", "trigger", "status",
    "started_at", "finished_at", "timestamp", "duration",
    "residual_rms_before", "residual_rms_after", "flag_bits", "timing",
) + ("part_id", "recipe", "release", "part", "verdict", "calibration", "tensor_set")

#: the envelope's keys as docs/service.md lists them (generated: ``moi run --payload-reference``): (keys, meaning)
ENVELOPE_DOC: tuple[tuple[tuple[str, ...], str], ...] = (
    (("uuid",), "the measurement's UUID: **dedupe by it** (QoS 1 may deliver twice)"),
    (("seq",), "the appliance's measurement sequence number (failed ones count too)"),
    (("device_id", "software_version", "trigger"), "who measured, with what, started by whom (button / modbus / mqtt)"),
    (("status",), "`ok`"),
    (("started_at", "finished_at", "timestamp", "duration"),
     "ISO 8601 UTC with ms; `timestamp` = finished_at as Unix time, s; `duration`, s"),
    (("residual_rms_before", "residual_rms_after"), "residual RMS of the declared model and of the final one, rad"),
    (("flag_bits",), "the quality flags as the Modbus bit field"),
    (("timing",), "released after request, capture length, capture end reason, samples"),
    (("payload_schema",), f"version of this envelope ({PAYLOAD_SCHEMA}; what each version changed: CHANGELOG.md)"),
    (("part_id",), "the part's serial number (PLC registers 100–109, MQTT `part_id`), null when none was given"),
    (("recipe",), "the recipe the release was judged with: `name`, `number`, `version` (SHA-256 of the file, 16 hex "
     "digits), `quantity`, `nominal`, `lower`, `upper`, `rule`, `uncertain`, `coverage_factor`, `releases`, "
     "`quality`; null without a recipe"),
    (("release",), "this release: `index` of `of`, `part_uuid`, `quantity`, `verdict`, `value`, `u_c`, `U`, "
     "`deviation`, `zone`, `reasons`, `abandoned` (an unfinished earlier part, if this release started a new one)"),
    (("part",), "on the release that completes the part: `uuid`, `part_id`, `measurements` (their UUIDs), `values`, "
     "`used`, `excluded` (index and reason), `mean`, `std`, `u_typeA`, `u_fit`, `u_systematic`, `z`, `verdict`, "
     "`u_c`, `U`, `deviation`, `zone`, `reasons`; else null"),
    (("verdict",), "the part's verdict (`OK`, `NOK`, `INVALID`) on the release that completes it, else null"),
    (("calibration",), "the rig's calibration: `date`, `valid_until`, `due`, `stiffness`, `stiffness_std`; null when "
     "the rig file has no `[calibration]`"),
    (("tensor_set",), "for a tensor recipe: the orientation this release counted for and the set's progress after "
     "it (docs/tensor.md); else null"),
)


def envelope_markdown() -> str:
    """The envelope's table in docs/service.md (``moi run --payload-reference``)."""
    rows = ["| key | meaning |", "|---|---|"]
    rows += [f"| {', '.join(f'`{k}`' for k in keys)} | {meaning} |" for keys, meaning in ENVELOPE_DOC]
    return "\n".join(rows) + "\n"


#: the part keys of the envelope (``service.parts.outcome.PartOutcome.to_dict``: what ``PartTracker.release`` made,
#: the rig's calibration state and, for a tensor recipe, the orientation the release counted for)
PART_KEYS = ENVELOPE_KEYS[-7:]


def iso_utc(t: float) -> str:
    """Unix time (s) → ISO 8601 UTC with milliseconds, e.g. 2025-01-31T12:00:00.123+00:00."""
    return datetime.fromtimestamp(t, UTC).isoformat(timespec="milliseconds")


def fmt_time(t: float | None) -> str:
    """Unix time (s) → "YYYY-MM-DD HH:MM:SS" in UTC, as a person reads it ("-": none)."""
    if t is None:
        return "-"
    return datetime.fromtimestamp(t, UTC).strftime("%Y-%m-%d %H:%M:%S")


def result_payload(result: Mapping[str, Any], *, uuid: str, seq: int, device_id: str, trigger: str,
                   started_at: float, finished_at: float, software_version: str,
                   timing: Mapping[str, Any] | None = None, part: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The result payload (JSON-ready dict). started_at/finished_at: Unix time, s.

    part: the part keys (PART_KEYS: part_id, recipe, release, part, verdict,
    calibration); missing ones are null, so every payload has them.
    """
    clash = set(ENVELOPE_KEYS) & set(result)
    if clash:  # the result object grew a key the envelope uses: fail loudly rather than overwrite
        raise ValueError(f"result keys {sorted(clash)} collide with the payload envelope")
    baseline = result.get("baseline") or {}
    envelope = {
        "payload_schema": PAYLOAD_SCHEMA,
        "uuid": str(uuid),
        "seq": int(seq),
        "device_id": device_id,
        "software_version": software_version,
        "trigger": trigger,
        "status": "ok",
        "started_at": iso_utc(started_at),
        "finished_at": iso_utc(finished_at),
        "timestamp": float(finished_at),
        "duration": float(finished_at - started_at),
        "residual_rms_before": baseline.get("residual_rms"),
        "residual_rms_after": result.get("residual_rms"),
        "flag_bits": flag_bits(result.get("flags") or ()),
        "timing": dict(timing or {}),
    }
    part = part or {}
    unknown = set(part) - set(PART_KEYS)
    if unknown:
        raise ValueError(f"unknown part keys {sorted(unknown)}; expected {PART_KEYS}")
    envelope.update({k: part.get(k) for k in PART_KEYS})
    return {**envelope, **result}


#: result schema → what makes a result JSON of it one of the next schema: the keys added then, with the value every
#: result had before them (CHANGELOG.md). A row the previous release stored reads as this schema's; a new result
#: schema adds its line here (``tests/service/publish/web/test_service_quality.py`` holds it to ``SCHEMA_VERSION``).
_NEXT_SCHEMA: dict[int, dict[str, Any]] = {
    4: {"measures": "angle"},  # schema 5: what the sensor read; before it, always the angle
    5: {},  # schema 6: keys added inside model_form.segments only (t_free, ...), which from_dict defaults
    6: {"periods": None},  # schema 7: the periods and g, none computed before; warnings, omega_n_from and
    #                         omega_n_effects, which from_dict derives from the flags and effects
    7: {},  # schema 8: J_std_calibration and J_std_model removed (lines of the budget), which from_dict does not read
    # schema 9: where ω_n is read; every result before it read ω_n as the small-swing limit of its laws
    8: {"omega_n_read_at": {"amplitude": 0.0, "basis": "small-swing limit", "limit": None, "limit_std": None}},
}


def stored_result(payload: Mapping[str, Any] | None) -> IdentificationResult | None:
    """The result a stored or published payload carries, typed (``IdentificationResult.from_dict``: the envelope is
    not read; a result of the previous schema is read with the keys added since, ``_NEXT_SCHEMA``); None when it
    carries none (a failed or aborted measurement) or one of an older schema (a row an older release stored: what it
    holds beyond the store's columns is not shown)."""
    if not payload or "schema" not in payload:
        return None
    while (schema := payload["schema"]) in _NEXT_SCHEMA:
        payload = {**_NEXT_SCHEMA[schema], **payload, "schema": schema + 1}
    try:
        return IdentificationResult.from_dict(payload)
    except ResultSchemaError:
        return None


def not_decidable(payload: Mapping[str, Any] | None) -> bool:
    """True when a result's verdict cannot decide (``PartOutcome.not_decidable``); False without a payload."""
    return payload is not None and PartOutcome.from_dict(payload).not_decidable
