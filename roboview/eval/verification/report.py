"""What a verification returns: named checks, each passed or not with its measured figure."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class Check:
    name: str
    passed: bool
    detail: str


@dataclass
class Report:
    checks: list[Check]
    seconds: float
    verdict: str | None = None  # the conformance verdict (a benchmark's verification)
    # A results folder's coverage of the protocol it claims: protocol, covered splits, partial.
    coverage: dict = field(default_factory=dict)
    # The replay: n, detect, confidence, drawn_at, passed, disagreements (None: not replayed).
    replay: dict | None = None

    @property
    def passed(self) -> bool:
        return all(c.passed for c in self.checks)

    def record(self, unreplayed: str = "not replayed (--replay=0)") -> dict:
        """verify.json, the one shape `roboview-verify` and a staged bundle both write: `passed`, every check,
        the protocol and its coverage (`covered` splits, `partial`) and the replay (None: not replayed, and said
        so as a check whose `passed` is None). A bundle adds its stacks and identity beside these keys."""
        checks = [{"name": c.name, "passed": c.passed, "detail": c.detail} for c in self.checks]
        if self.replay is None:
            checks.append({"name": "replay", "passed": None, "detail": unreplayed})
        return {
            "passed": self.passed,
            "checks": checks,
            "protocol": self.coverage.get("protocol", ""),
            "covered": list(self.coverage.get("covered", [])),
            "partial": self.coverage.get("partial", True),
            "replay": self.replay,
        }


def listed(items: list, limit: int = 3) -> str:
    """The first `limit` items, comma-separated, and how many there are in all when more."""
    return ", ".join(map(str, items[:limit])) + (f" … ({len(items)} in all)" if len(items) > limit else "")
