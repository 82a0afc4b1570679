"""Synthetic episode tables with a known bias, for validating the statistics against the truth.

A policy "with logit-SD τ bias" succeeds on value v in context c with p = logistic(logit(SR) + β_v),
β_v ~ N(0, τ²) drawn per table; τ = 0 is no bias at all. Outcomes are independent Bernoulli draws.
The noise-free Bias Coefficient of a table is the paper's CV computed from its true p(v, c).
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd


def simulate_split(
    rng: np.random.Generator, n_values: int, n_contexts: int, repeats: int, tau: float, sr: float
) -> tuple[pd.DataFrame, float]:
    """An episodes table of one single-factor split, and the noise-free CV of its true p(v, c)."""
    beta = rng.normal(0.0, tau, n_values)
    p = 1 / (1 + np.exp(-(math.log(sr / (1 - sr)) + beta)))[:, None].repeat(n_contexts, axis=1)
    success = rng.random((n_values, n_contexts, repeats)) < p[:, :, None]
    v, c, r = np.meshgrid(np.arange(n_values), np.arange(n_contexts), np.arange(repeats), indexing="ij")
    v, c = v.ravel(), c.ravel()
    frame = pd.DataFrame(
        {
            "policy": "p",
            "split": "color",
            "factor": "color",
            "value": [f"v{x}" for x in v],
            "context_id": [f"c{x}" for x in c],
            "instance_id": [f"{a}/{b}" for a, b in zip(v, c)],
            "repeat": r.ravel(),
            "success": success.ravel(),
        }
    )
    return frame, float(np.mean(p.std(axis=0) / p.mean(axis=0)))


def simulate_additive_factorial(
    rng: np.random.Generator, n_a: int, n_b: int, repeats: int, tau_a: float, b_range: float, sr: float
) -> pd.DataFrame:
    """A factorial split over (A, B) in one context with additive logit effects and no interaction:
    A's effects ~ N(0, τ_a²), B's spread evenly over ±b_range."""
    logit = (
        rng.normal(0, tau_a, n_a)[:, None]
        + np.linspace(-b_range, b_range, n_b)[None, :]
        + math.log(sr / (1 - sr))
    )
    success = rng.random((n_a, n_b, repeats)) < (1 / (1 + np.exp(-logit)))[:, :, None]
    rows = [
        {
            "policy": "p",
            "split": "A_x_B",
            "factor": "A|B",
            "value": f"a{a}|b{b}",
            "context_id": "c*",
            "instance_id": f"{a}/{b}",
            "repeat": r,
            "success": bool(success[a, b, r]),
        }
        for a in range(n_a)
        for b in range(n_b)
        for r in range(repeats)
    ]
    return pd.DataFrame(rows)
