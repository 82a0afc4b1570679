"""Why raw CV misleads, measured: the statistics on simulated policies whose bias is known.

    python -m benchmarks.stats_calibration [--sims=40] [--values=9] [--contexts=4] [--repeats=5] [--sr=0.7]

For τ = 0 (no bias), 0.3 and 0.6 (logit SD of the value effects) it simulates `--sims` tables of
one single-factor split (`roboview.eval.statistics.simulate`), computes the metrics exactly as `roboview.pipelines.report` does,
and prints per τ: the noise-free CV of the true success probabilities, the mean paper CV, cv_null
and cv_excess, and how often each test says p < 0.05 (type-I error at τ = 0, power above it):
the GLM likelihood-ratio `p_value`, the CV permutation test `p_value_cv`, and "any value with
q < 0.05". It ends with the planner's predicted power for the same design.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from roboview.eval.statistics.metrics import MetricsConfig, split_metrics
from roboview.eval.statistics.significance import lrt_power
from roboview.eval.statistics.simulate import simulate_split
from roboview.pipelines._cli import cli_main


@dataclass
class CalibrationConfig:
    # Simulated tables per τ.
    sims: int = 40
    # Values of the simulated single-factor split.
    values: int = 9
    # Contexts per value.
    contexts: int = 4
    # Repeats per (value, context): 2 or more (one repeat leaves the CV's permutation floor undefined).
    repeats: int = 5
    # Mean success rate of the simulated policy.
    sr: float = 0.7
    # True biases τ to simulate (logit SD of the value effects); 0 measures the type-I error.
    taus: list[float] = field(default_factory=lambda: [0.0, 0.3, 0.6])

    def __post_init__(self) -> None:
        for name in ("sims", "values", "contexts", "repeats"):
            if getattr(self, name) < 1:
                raise ValueError(f"--{name}={getattr(self, name)} must be a positive count")
        if self.repeats < 2:
            raise ValueError(f"--repeats={self.repeats}: the CV's permutation floor needs 2 or more repeats")
        if not 0.0 < self.sr < 1.0:
            raise ValueError(f"--sr={self.sr} must lie in (0, 1)")
        if not self.taus or any(t < 0 for t in self.taus):
            raise ValueError(f"--taus={','.join(map(str, self.taus))}: give one or more biases ≥ 0")


def run(cfg: CalibrationConfig) -> None:
    metrics = MetricsConfig(n_perm=200, n_glm=100)
    print(
        f"{cfg.values} values × {cfg.contexts} contexts × {cfg.repeats} repeats, SR ≈ {cfg.sr}, "
        f"{cfg.sims} simulated tables per τ"
    )
    print(
        f"{'τ':>5}{'true CV':>9}{'CV':>8}{'cv_null':>9}{'cv_excess':>11}{'p<.05 GLM':>11}{'p<.05 CV':>10}"
        f"{'any q<.05':>11}{'predicted':>11}{'s/table':>9}"
    )
    for tau in cfg.taus:
        rng = np.random.default_rng(0)
        rows = []
        start = time.perf_counter()
        for _ in range(cfg.sims):
            table, true_cv = simulate_split(rng, cfg.values, cfg.contexts, cfg.repeats, tau, cfg.sr)
            m = split_metrics(table, metrics)
            qs = [s["q_value"] for s in m["per_value"].values() if s["q_value"] is not None]
            rows.append(
                (
                    true_cv,
                    m["cv"],
                    m["cv_null"],
                    m["cv_excess"],
                    m["p_value"] < 0.05,
                    m["p_value_cv"] < 0.05,
                    min(qs, default=1.0) < 0.05,
                )
            )
        mean = np.mean(np.array(rows, dtype=float), axis=0)
        predicted = lrt_power(cfg.values, cfg.contexts, cfg.repeats, tau, cfg.sr) if tau > 0 else 0.05
        per_table = (time.perf_counter() - start) / cfg.sims
        print(
            f"{tau:>5.2f}{mean[0]:>9.3f}{mean[1]:>8.3f}{mean[2]:>9.3f}{mean[3]:>11.3f}{mean[4]:>11.2f}"
            f"{mean[5]:>10.2f}{mean[6]:>11.2f}{predicted:>11.2f}{per_table:>9.2f}"
        )


def main(args: list[str] | None = None) -> None:
    cli_main(CalibrationConfig, run, args=args)


if __name__ == "__main__":
    main()
