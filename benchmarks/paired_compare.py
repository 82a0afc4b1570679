"""The adaptive paired comparison (`roboview-compare`) by simulation: type-I error under optional stopping, power
and rounds used, against the fixed design that runs every round and tests once, and against an e-process
(docs/adaptive.md).

The e-process is the mixture likelihood ratio of the discordant pairs, the anytime-valid alternative: B wins each
discordant pair with probability θ, θ ~ Beta(1, 1) against θ = ½, so E_k = 2^D·B(1 + W, 1 + D − W) (D discordant
pairs, W won by B); it declares a difference once E_k ≥ 1/α (Ville's inequality), at any look, planned or not.

    python -m benchmarks.paired_compare [--sims=2000] [--pairs=57] [--max_repeats=10]

Two policies on the same `pairs` instances per round; instance i succeeds with p_i ~ U(0.3, 0.9) for A and
p_i + δ (capped at 0.99) for B; common random numbers: B's uniform is A's with probability 0.5, else fresh.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import special

from roboview.eval.statistics.sequential_compare import SR_VERDICTS, CompareDesign, sr_looks
from roboview.eval.statistics.significance import paired_success_test
from roboview.pipelines._cli import cli_main


def simulate(rng, pairs: int, rounds: int, delta: float) -> tuple[np.ndarray, np.ndarray]:
    p = rng.uniform(0.3, 0.9, pairs)[:, None]
    u = rng.random((pairs, rounds))
    v = np.where(rng.random((pairs, rounds)) < 0.5, u, rng.random((pairs, rounds)))
    return u < p, v < np.minimum(p + delta, 0.99)


def e_process_look(a: np.ndarray, b: np.ndarray, alpha: float) -> int | None:
    """The first round after which the Beta(1, 1)-mixture e-value of the discordant pairs reaches 1/α (None: none
    of the rounds)."""
    d = np.cumsum(np.sum(a != b, axis=0))
    w = np.cumsum(np.sum(b & ~a, axis=0))
    log_e = d * np.log(2) + special.betaln(1 + w, 1 + d - w)
    hit = np.flatnonzero(log_e >= np.log(1 / alpha))
    return int(hit[0]) + 1 if len(hit) else None


def study(sims: int, pairs: int, max_repeats: int, delta: float, seed: int = 0) -> dict[str, float]:
    rng = np.random.default_rng(seed)
    design = CompareDesign(max_repeats=max_repeats)
    decided, rounds = 0, []
    e_decided, e_rounds = 0, []
    fixed = np.zeros(max_repeats)  # verdicts of the fixed test after r rounds, r = 1 … K
    for _ in range(sims):
        a, b = simulate(rng, pairs, max_repeats, delta)
        r = sr_looks(a, b, design)
        decided += r["verdict"] in SR_VERDICTS
        rounds.append(r["look"] or max_repeats)
        e_look = e_process_look(a, b, design.alpha)
        e_decided += e_look is not None
        e_rounds.append(e_look or max_repeats)
        fixed += [
            paired_success_test(a[:, :k].ravel(), b[:, :k].ravel()) < design.alpha
            for k in range(1, max_repeats + 1)
        ]
    power = decided / sims
    # The fewest rounds with which the fixed design matches the adaptive one's power (K if none does).
    equal = next((k + 1 for k in range(max_repeats) if fixed[k] / sims >= power), max_repeats)
    return {
        "delta": delta,
        "adaptive_rejects": power,
        "mean_rounds": float(np.mean(rounds)),
        "e_process_rejects": e_decided / sims,
        "e_process_mean_rounds": float(np.mean(e_rounds)),
        "fixed_rejects": fixed[-1] / sims,
        "fixed_rounds": max_repeats,
        "fixed_rounds_equal_power": equal,
    }


@dataclass
class PairedCompareConfig:
    # Simulated comparisons per SR gap.
    sims: int = 2000
    # Instance pairs per round (both policies).
    pairs: int = 57
    # Planned rounds (looks) of the adaptive comparison, and the rounds of the fixed design.
    max_repeats: int = 10

    def __post_init__(self) -> None:
        for name in ("sims", "pairs", "max_repeats"):
            if getattr(self, name) < 1:
                raise ValueError(f"--{name}={getattr(self, name)} must be a positive count")


def run(cfg: PairedCompareConfig) -> None:
    print(
        "| δ (SR) | adaptive: verdicts | mean rounds | e-process: verdicts | mean rounds | fixed, all K rounds: "
        "verdicts | fixed: rounds for the adaptive power |"
    )
    print("|---|---|---|---|---|---|---|")
    for delta in (0.0, 0.05, 0.1, 0.2):
        r = study(cfg.sims, cfg.pairs, cfg.max_repeats, delta)
        print(
            f"| {delta:g} | {r['adaptive_rejects']:.3f} | {r['mean_rounds']:.2f} | {r['e_process_rejects']:.3f} | "
            f"{r['e_process_mean_rounds']:.2f} | {r['fixed_rejects']:.3f} | "
            f"{r['fixed_rounds_equal_power']} |",
            flush=True,
        )


def main(args: list[str] | None = None) -> None:
    cli_main(PairedCompareConfig, run, args=args)


if __name__ == "__main__":
    main()
