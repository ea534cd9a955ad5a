"""docs/service.md's table of the result envelope is generated from the code (``moi run --payload-reference``)."""

from __future__ import annotations

from collections import Counter

from service.cli import main
from service.publish.payload import ENVELOPE_DOC, ENVELOPE_KEYS, PAYLOAD_SCHEMA, envelope_markdown
from tests.service.conftest import REPO


def test_every_envelope_key_is_documented_once_and_the_schema_is_the_codes():
    documented = Counter(k for keys, _ in ENVELOPE_DOC for k in keys)
    assert set(documented) == set(ENVELOPE_KEYS) and set(documented.values()) == {1}
    assert f"| `payload_schema` | version of this envelope ({PAYLOAD_SCHEMA};" in envelope_markdown()


def test_the_docs_hold_the_generated_table(capsys):
    text = (REPO / "docs" / "service.md").read_text(encoding="utf-8")
    start = text.index("-->\n", text.index("<!-- payload-reference:start")) + 4
    end = text.index("<!-- payload-reference:end -->")
    assert text[start:end] == envelope_markdown(), "docs/service.md is stale: regenerate with `moi run --payload-reference`"
    assert main(["run", "--payload-reference"]) == 0
    assert capsys.readouterr().out == envelope_markdown()
