"""The episode row: the one record an episode leaves in `episodes.parquet`, declared once and written by every
path that produces episodes (the rollout, the row of an episode whose worker died, and the converters of
lerobot-eval's and vla-eval's results).

A row is the instance's record columns, then the episode's own: `repeat`, `episode_seed`, `success`,
`steps`, `duration_s`, `policy`, `failure_reason` (empty on success), `isolation` (the certificate's hashes),
`status` and, where known, `conformance`; a policy's own columns (VLM usage, the refined instruction) follow.
`status` is `ok` (a success or the policy's own failure: counted) or `infra_error` (infrastructure ended the
episode: counted in no rate or test, re-run on resume). docs/formats.md documents every column.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from roboview.tasks.repetition import UNIT_COLUMN

STATUS = "status"
STATUS_OK = "ok"
INFRA_ERROR = "infra_error"
STATUSES = (STATUS_OK, INFRA_ERROR)


@dataclass(frozen=True)
class EpisodeRow:
    # The instance's record columns (instance_id, split, factor, value, context_id, every factor's value, ...).
    record: Mapping[str, Any]
    repeat: int
    episode_seed: int
    success: bool
    steps: int | None
    duration_s: float | None
    policy: str | None
    failure_reason: str = ""
    # What the repeat varied besides the seed ("init_state=12" on LIBERO's scenes; roboview.tasks.repetition),
    # "" where the seed is the episode's whole randomness (then no column is written).
    unit: str = ""
    isolation: Any = None
    status: str = STATUS_OK
    # The conformance verdict of the stack the episode ran on; None: the evaluator adds it when it stores the row.
    conformance: str | None = None
    # A policy's own columns; never overriding the row's.
    extra: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.status not in STATUSES:
            raise ValueError(f"episode status {self.status!r}; allowed: {', '.join(STATUSES)}")
        if self.success and self.failure_reason:
            raise ValueError(f"a successful episode has no failure reason (got {self.failure_reason!r})")

    def as_dict(self) -> dict[str, Any]:
        row = {
            **self.record,
            "repeat": self.repeat,
            "episode_seed": self.episode_seed,
            "success": bool(self.success),
            "steps": self.steps,
            "duration_s": self.duration_s,
            "policy": self.policy,
            "failure_reason": self.failure_reason,
            "isolation": self.isolation,
            STATUS: self.status,
        }
        if self.unit:
            row[UNIT_COLUMN] = self.unit
        if self.conformance is not None:
            row["conformance"] = self.conformance
        return row | {k: v for k, v in self.extra.items() if k not in row}


# The columns every episode row carries in episodes.parquet, their kind and whether they may be null: what a
# verifier checks before anything else (the instance's record columns are checked against the benchmark).
SCHEMA: dict[str, tuple[str, bool]] = {
    "instance_id": ("string", False),
    "split": ("string", False),
    "value": ("string", False),
    "context_id": ("string", False),
    "repeat": ("integer", False),
    "episode_seed": ("integer", False),
    "success": ("bool", False),
    "steps": ("integer", True),
    "duration_s": ("float", True),
    "policy": ("string", True),
    "failure_reason": ("string", True),
    STATUS: ("string", False),
}
# Columns whose values are drawn from a fixed set (`conformance` where a row records it).
ALLOWED = {STATUS: STATUSES, "conformance": ("identical", "equivalent", "different")}
