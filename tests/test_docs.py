"""docs/format.md documents every entry of the schema."""

from __future__ import annotations

from pathlib import Path

from wristmimic.format import schema
from wristmimic.humanoid.roles import ROLE_NAMES

DOC = (Path(__file__).resolve().parents[1] / "docs" / "format.md").read_text()


def test_every_array_attribute_and_role_is_documented() -> None:
    missing = [
        n
        for n in [
            *schema.SEQUENCE_ARRAYS,
            *schema.OPTIONAL_SEQUENCE_ARRAYS,
            *schema.OBJECT_ARRAYS,
            *schema.ROOT_ATTRS,
            *ROLE_NAMES,
        ]
        if f"`{n}`" not in DOC
    ]
    assert not missing, f"not in docs/format.md: {missing}"
    assert schema.SCHEMA_VERSION in DOC
