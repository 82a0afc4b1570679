"""The protocols a benchmark can be evaluated under, declared in its manifest (`benchmark.json`, `protocols`).

A protocol names the splits it covers (every value of each) and how many episodes each instance gets: a fixed
`n_repeats` per split, or the adaptive design (`max_repeats`, `alpha`, `tau`, `power`; docs/adaptive.md) for its
single-factor splits, whose factorial splits keep their fixed repeats. A results folder's run.json names the protocol
it claims (`roboview-evaluate --eval.protocol=NAME`); verification judges its rows against the benchmark's declaration,
never against the folder's own run.json: a covered split misses no row and holds none beyond the protocol, and a
folder that covers only some of the protocol's splits is `partial` (ranked per split only).

Every benchmark declares `paper` (5 repeats per single-factor instance, 10 per factorial one: the paper's protocol)
and `adaptive`; a preset may add its own (`tiny`: `quick`, 3 repeats, the demo's and the first board's). A benchmark built before
protocols were declared gets these defaults from its splits.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

PAPER_REPEATS, FACTORIAL_REPEATS = 5, 10
ADAPTIVE_DESIGN = {"max_repeats": 10, "alpha": 0.05, "tau": 0.3, "power": 0.8}
# Protocols a preset declares beyond the defaults: name → repeats per instance, every split.
PRESET_PROTOCOLS: dict[str, dict[str, int]] = {"tiny": {"quick": 3}}


def is_factorial(split: str) -> bool:
    """A two-factor split (`color_x_camera_pose`): fixed repeats under every protocol."""
    return "_x_" in split


@dataclass(frozen=True)
class Protocol:
    name: str
    splits: tuple[str, ...]
    # Fixed repeats per split (for an adaptive protocol: its factorial splits only).
    n_repeats: dict[str, int]
    # The adaptive design (max_repeats, alpha, tau, power); None: fixed repeats.
    adaptive: dict[str, float] | None = None

    def adaptive_split(self, split: str) -> bool:
        return self.adaptive is not None and split not in self.n_repeats

    def describe(self) -> str:
        if self.adaptive is None:
            counts = sorted(set(self.n_repeats.values()))
            return (
                f"{self.name}: {len(self.splits)} splits, every value, {'/'.join(map(str, counts))} repeats"
            )
        return (
            f"{self.name}: {len(self.splits)} splits, every value, adaptive up to "
            f"{int(self.adaptive['max_repeats'])} repeats"
        )

    def to_json(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "splits": list(self.splits),
            "values": "all",
            "n_repeats": dict(self.n_repeats),
        }
        if self.adaptive is not None:
            out["adaptive"] = dict(self.adaptive)
        return out

    @classmethod
    def from_json(cls, name: str, data: dict[str, Any]) -> Protocol:
        return cls(
            name,
            tuple(data["splits"]),
            {s: int(n) for s, n in (data.get("n_repeats") or {}).items()},
            dict(data["adaptive"]) if data.get("adaptive") else None,
        )


def default_protocols(splits: list[str], preset: str = "") -> dict[str, Protocol]:
    """`paper`, `adaptive` and the preset's own, over `splits`."""
    paper = {s: FACTORIAL_REPEATS if is_factorial(s) else PAPER_REPEATS for s in splits}
    out = {
        "paper": Protocol("paper", tuple(splits), paper),
        "adaptive": Protocol(
            "adaptive",
            tuple(splits),
            {s: FACTORIAL_REPEATS for s in splits if is_factorial(s)},
            dict(ADAPTIVE_DESIGN),
        ),
    }
    for name, repeats in PRESET_PROTOCOLS.get(preset, {}).items():
        out[name] = Protocol(name, tuple(splits), dict.fromkeys(splits, repeats))
    return out


def protocols_json(splits: list[str], preset: str) -> dict[str, dict]:
    """What a new build writes under the manifest's `protocols`."""
    return {name: p.to_json() for name, p in default_protocols(splits, preset).items()}


def declared(manifest: dict, splits: list[str]) -> dict[str, Protocol]:
    """The manifest's protocols; a manifest that declares none gets the defaults over its `splits`."""
    if manifest.get("protocols"):
        return {name: Protocol.from_json(name, data) for name, data in manifest["protocols"].items()}
    return default_protocols(splits, manifest.get("suite", {}).get("preset", ""))


def choose(protocols: dict[str, Protocol], name: str, flag: str = "--eval.protocol") -> Protocol:
    """The protocol `name` (ValueError listing those the benchmark declares)."""
    if name not in protocols:
        raise ValueError(
            f"{flag}={name!r} is not a protocol of this benchmark; it declares: "
            + "; ".join(p.describe() for p in protocols.values())
        )
    return protocols[name]
