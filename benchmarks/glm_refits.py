"""The cost of the split test's permutation refits: one batched Newton solve (`batch_glm.value_lrt`, what
`significance.factor_lrt` uses for a table with one cell per (value, context)) against two statsmodels fits per
permuted table, on simulated sparse splits, with the largest difference between their statistics
(docs/statistics.md, "p_value"; docs/performance.md).

    python -m benchmarks.glm_refits [--draws=2000] [--statsmodels_draws=200] [--tau=0.6] [--sr=0.7]
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from roboview.eval.statistics import significance
from roboview.eval.statistics.batch_glm import value_lrt
from roboview.eval.statistics.simulate import simulate_split
from roboview.eval.statistics.tables import CellTable
from roboview.pipelines._cli import cli_main

# Values × contexts × repeats: sparse tables, where the refits calibrate the test.
SHAPES = ((9, 4, 5), (21, 11, 3))


@dataclass
class RefitConfig:
    # Permuted tables refitted by the batched solver, per shape.
    draws: int = 2000
    # ... and by statsmodels (two fits each), the first of the same tables.
    statsmodels_draws: int = 200
    # Logit SD of the simulated value effects.
    tau: float = 0.6
    # Mean success rate of the simulated splits.
    sr: float = 0.7

    def __post_init__(self) -> None:
        if not 1 <= self.statsmodels_draws <= self.draws:
            raise ValueError(
                f"statsmodels_draws={self.statsmodels_draws} must be between 1 and draws={self.draws}"
            )


def run(cfg: RefitConfig) -> None:
    print("| values × contexts × repeats | batched ms/refit | statsmodels ms/refit | max |difference| |")
    print("|---|---|---|---|")
    rng = np.random.default_rng(0)
    for values, contexts, repeats in SHAPES:
        episodes, _ = simulate_split(rng, values, contexts, repeats, cfg.tau, cfg.sr)
        table = CellTable.build(episodes, ("value",), ["value", "context_id"])
        k, n = table.k, table.n
        value, context = table.codes(["value"]), table.codes(["context_id"])
        permuted = table.permuted_k(["context_id"], cfg.draws, rng)
        keep = significance.informative(k, n, context)
        _, value_c = np.unique(value[keep], return_inverse=True)
        _, context_c = np.unique(context[keep], return_inverse=True)
        full = significance.design_matrix([context_c, value_c])
        reduced = significance.design_matrix([context_c])
        value_lrt(permuted[:1, keep], n[keep], value_c, context_c)  # first calls, out of the timing
        significance.lrt_statistic(permuted[0, keep], n[keep], full, reduced)
        start = time.perf_counter()
        batched = value_lrt(permuted[:, keep], n[keep], value_c, context_c)
        fast = (time.perf_counter() - start) / cfg.draws
        start = time.perf_counter()
        one_by_one = [
            significance.lrt_statistic(kp[keep], n[keep], full, reduced)
            for kp in permuted[: cfg.statsmodels_draws]
        ]
        slow = (time.perf_counter() - start) / cfg.statsmodels_draws
        diff = float(np.abs(batched[: cfg.statsmodels_draws] - one_by_one).max())
        print(
            f"| {values} × {contexts} × {repeats} | {fast * 1e3:.3f} | {slow * 1e3:.2f} | {diff:.1e} |",
            flush=True,
        )


def main(args: list[str] | None = None) -> None:
    cli_main(RefitConfig, run, args=args)


if __name__ == "__main__":
    main()
