"""Adaptive against fixed-n evaluation on simulated splits with a known bias: episodes to a decision.

    python -m benchmarks.adaptive --output=outputs/bench/adaptive.json [--sims=100]

For each design (values × contexts at SR 0.7, the paper's camera_euler / camera_pose shapes and a small
one) and true bias τ ∈ {0, 0.3, 0.6} (logit SD), `eval.adaptive.simulate` runs the group-sequential
design (α = 0.05, futility against τ = 0.6 at power 0.8, at most `max_repeats` rounds) on real binomial
tables with the real test. The fixed-n reference is the smallest number of repeats whose LRT power at
τ = 0.6 (`eval.stats.lrt_power`, asymptotic; sparse tables fall short of it, so it favours the fixed
design) reaches the adaptive design's simulated power at τ = 0.6. `saving` = 1 − adaptive episodes / fixed.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

from eval.adaptive import Design, simulate
from eval.stats import lrt_power
from pipelines._cli import cli_main

DESIGNS = ((9, 4, 10), (9, 11, 6), (21, 11, 4))  # values, contexts, max_repeats


@dataclass
class AdaptiveBenchConfig:
    # JSON file to write.
    output: str = "outputs/bench/adaptive.json"
    # Simulated splits per design and τ.
    sims: int = 100

    def __post_init__(self) -> None:
        if self.sims < 10:
            raise ValueError(f"--sims={self.sims} must be ≥ 10")


def run(cfg: AdaptiveBenchConfig) -> dict:
    results = []
    for n_values, n_contexts, max_repeats in DESIGNS:
        design = Design(alpha=0.05, tau=0.6, power=0.8, max_repeats=max_repeats)
        start = time.perf_counter()
        rows = {tau: simulate(n_values, n_contexts, 0.7, tau, design, cfg.sims, seed=7) for tau in (0.0, 0.3, 0.6)}
        power = rows[0.6]["rejection_rate"]
        fixed = next((n for n in range(1, 41) if lrt_power(n_values, n_contexts, n, 0.6, 0.7) >= power), 40)
        fixed_episodes = fixed * n_values * n_contexts
        results.append({"values": n_values, "contexts": n_contexts, "max_repeats": max_repeats,
                        "adaptive": {str(t): r for t, r in rows.items()}, "fixed_repeats_equal_power": fixed,
                        "fixed_episodes": fixed_episodes,
                        "saving": {str(t): round(1 - r["mean_episodes"] / fixed_episodes, 3) for t, r in rows.items()},
                        "seconds": round(time.perf_counter() - start, 1)})
        print(f"[adaptive] {n_values}×{n_contexts}: type-I {rows[0.0]['rejection_rate']:.3f}, power(0.6) {power:.2f}; "
              f"episodes τ=0/0.3/0.6: " + "/".join(f"{rows[t]['mean_episodes']:.0f}" for t in (0.0, 0.3, 0.6))
              + f" vs fixed {fixed_episodes} ({fixed} repeats)", flush=True)
    out = {"sims": cfg.sims, "alpha": 0.05, "tau_design": 0.6, "sr": 0.7, "designs": results}
    Path(cfg.output).parent.mkdir(parents=True, exist_ok=True)
    Path(cfg.output).write_text(json.dumps(out, indent=2))
    return out


def main(args: list[str] | None = None) -> dict:
    return cli_main(AdaptiveBenchConfig, run, args=args)


if __name__ == "__main__":
    main()
