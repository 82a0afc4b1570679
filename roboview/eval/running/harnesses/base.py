"""What every harness reader returns: one row per episode and the columns RoboView's mapping defaults to."""

from __future__ import annotations

from dataclasses import dataclass, field

import pandas as pd

MAP_FIELDS = ("factor", "value", "context", "success", "repeat", "policy")
REQUIRED = ("factor", "value", "context", "success")


@dataclass(frozen=True)
class HarnessTable:
    """One row per episode of another harness, and what RoboView's columns default to."""

    # One row per episode; the harness's own fields as columns.
    table: pd.DataFrame
    # --map.<field> → the column it defaults to (fields in MAP_FIELDS); absent: no default.
    mapping: dict[str, str]
    # What was read, in words (the files and what they held), for the report.
    source: str
    # --map.<field> → why the harness's results give it no default (said when the field is left unmapped).
    missing: dict[str, str] = field(default_factory=dict)


def scalar_fields(record: dict, prefix: str = "") -> dict:
    """The record's str / int / float / bool / None values, keys prefixed (nested values are left out)."""
    return {
        f"{prefix}{key}": value
        for key, value in record.items()
        if value is None or isinstance(value, (str, int, float, bool))
    }
