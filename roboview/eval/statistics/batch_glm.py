"""The split test's likelihood-ratio statistic for many tables at once.

A split's test is the binomial GLM `value + context` against `context` (`significance.factor_lrt`). Calibrating a
sequential design on its own look sequence means that statistic for thousands of simulated tables per look, where
one statsmodels fit per table would take minutes. The tables of a split share their layout (a value × context
grid), so Newton's method runs on all of them together, and the two-way structure makes each step cheap: the value
block of the Hessian is diagonal, so a step solves only the contexts' Schur complement (η_vc = a_v + b_c,
b_0 = 0). The context-only fit has a closed form (each context's success rate).

Contexts with only successes or only failures carry no information about the value and are left out, as
`factor_lrt` leaves them out: their cells get weight zero. A value that never fails (or never succeeds) sends
its coefficient to ±∞ and fits its cells exactly: it adds nothing to the maximised log-likelihood and is left out
of the fit; the statistic is the limit statsmodels' iterations approach. `tests/eval/statistics/test_batch_glm.py` checks the statistic against `factor_lrt`'s.
"""

from __future__ import annotations

import numpy as np
from scipy.special import xlogy

ITERATIONS = 60  # Newton steps at most (a table typically needs 4–8)
RIDGE = 1e-9  # keeps the Hessian of a drifting (separated) coefficient invertible
MAX_STEP = 5.0  # per coefficient and step: a near-singular Hessian cannot throw a fit far off
CHUNK = 1024  # tables per Newton solve
HALVINGS = 30  # step halvings at most per Newton step


def _own_rate_llf(k: np.ndarray, n: np.ndarray) -> np.ndarray:
    """Σ k log(k/n) + (n − k) log(1 − k/n) over the last axis: the log-likelihood of cells at their own rate."""
    p = k / np.where(n > 0, n, 1)
    return (xlogy(k, p) + xlogy(n - k, 1 - p)).sum(axis=-1)


def _softplus(eta: np.ndarray) -> np.ndarray:
    """log(1 + e^η), stably (np.logaddexp(0, η)'s value, at a fifth of its cost here)."""
    return np.maximum(eta, 0.0) + np.log1p(np.exp(-np.abs(eta)))


def _expit(eta: np.ndarray) -> np.ndarray:
    """1 / (1 + e^−η), stably (scipy.special.expit's value, at a third of its cost here)."""
    e = np.exp(-np.abs(eta))
    return np.where(eta >= 0, 1.0, e) / (1.0 + e)


def _llf(k: np.ndarray, n: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    eta = a[:, :, None] + b[:, None, :]
    return np.einsum("tvc->t", k * eta - n * _softplus(eta))


def _newton_direction(
    k: np.ndarray, n: np.ndarray, a: np.ndarray, b: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Newton's direction for the additive fit η = a_v + b_c (b_0 = 0) on grids (tables, values, contexts), and
    each table's largest score component (0 at its maximum)."""
    mu = _expit(a[:, :, None] + b[:, None, :])
    w = n * mu * (1 - mu)
    r = k - n * mu
    # Sums over one axis as einsum: numpy's reduce over a short axis is 4–5× slower here.
    ga, gb = np.einsum("tvc->tv", r), np.einsum("tvc->tc", r)[:, 1:]
    wv = np.einsum("tvc->tv", w) + RIDGE
    x = w[:, :, 1:]
    xt = x.transpose(0, 2, 1)
    schur = -(xt @ (x / wv[:, :, None]))
    idx = np.arange(x.shape[2])
    schur[:, idx, idx] += np.einsum("tvc->tc", w)[:, 1:] + RIDGE
    rhs = gb - (xt @ (ga / wv)[:, :, None])[..., 0]
    db = np.linalg.solve(schur, rhs[..., None])[..., 0] if x.shape[2] else np.zeros_like(gb)
    da = (ga - (x @ db[:, :, None])[..., 0]) / wv
    return (
        np.clip(da, -MAX_STEP, MAX_STEP),
        np.clip(db, -MAX_STEP, MAX_STEP),
        np.maximum(np.abs(ga).max(axis=1, initial=0), np.abs(gb).max(axis=1, initial=0)),
    )


def _fit(k: np.ndarray, n: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Maximised log-likelihood of the additive fit from (a, b): Newton steps, each halved for a table until its
    log-likelihood does not fall (Newton alone can oscillate on a logistic likelihood from a poor start). A table
    leaves the iteration once its score vanishes, so the slowest tables do not hold the rest."""
    current = _llf(k, n, a, b)
    live = np.arange(len(k))
    for _ in range(ITERATIONS):
        kl, nl, al, bl = k[live], n[live], a[live], b[live]
        da, db, score = _newton_direction(kl, nl, al, bl)
        moving = score >= 1e-9
        if not moving.any():
            break
        live, kl, nl, al, bl = live[moving], kl[moving], nl[moving], al[moving], bl[moving]
        da, db, now = da[moving], db[moving], current[live]
        scale = np.ones(len(live))
        for _ in range(HALVINGS):
            trial = _llf(kl, nl, al + scale[:, None] * da, bl + scale[:, None] * np.pad(db, ((0, 0), (1, 0))))
            worse = trial < now - 1e-12 * np.abs(now)
            if not worse.any():
                break
            scale[worse] /= 2
        else:  # a table still worse after every halving keeps its coefficients
            scale[worse] = 0.0
            trial = np.where(worse, now, trial)
        a[live] = al + scale[:, None] * da
        b[live, 1:] = bl[:, 1:] + scale[:, None] * db
        current[live] = trial
    return current


def _grid_lrt(k: np.ndarray, n: np.ndarray) -> np.ndarray:
    """The statistic for grids (tables, values, contexts) of successes k in n episodes."""
    ks, ns = k.sum(axis=1), n.sum(axis=1)
    informative = (ks > 0) & (ks < ns)
    n = np.where(informative[:, None, :], n, 0.0)
    k = np.where(informative[:, None, :], k, 0.0)
    # A value that always succeeds (or always fails) in the informative contexts fits its cells exactly at
    # a_v = ±∞: they add nothing to the maximised log-likelihood, and leaving them out spares the slow drift.
    kv, nv = k.sum(axis=2), n.sum(axis=2)
    separated = ((kv == 0) | (kv == nv))[:, :, None]
    n_fit, k_fit = np.where(separated, 0.0, n), np.where(separated, 0.0, k)
    rate = np.clip(np.where(ns > 0, ks / np.where(ns > 0, ns, 1), 0.5), 1e-3, 1 - 1e-3)
    b = np.log(rate / (1 - rate))
    a = np.repeat(b[:, :1], k.shape[1], axis=1)
    full = _fit(k_fit, n_fit, a, b - b[:, :1])
    reduced = _own_rate_llf(ks, ns)  # the context-only fit (an uninformative context adds 0)
    return np.where(informative.any(axis=1), np.maximum(0.0, 2 * (full - reduced)), 0.0)


def value_lrt(k: np.ndarray, n: np.ndarray, value: np.ndarray, context: np.ndarray) -> np.ndarray:
    """2 (ℓ(value + context) − ℓ(context)) for each row of `k` (tables × cells), clipped at 0.

    Cells are distinct (value, context) pairs with codes 0..V−1 and 0..C−1; `n`: episodes per cell, shape
    (cells,) or like `k`. 0 for a table with no informative context.
    """
    k = np.atleast_2d(np.asarray(k, float))
    n = np.broadcast_to(np.asarray(n, float), k.shape)
    n_values, n_contexts = int(value.max()) + 1, int(context.max()) + 1
    flat = value * n_contexts + context
    if len(np.unique(flat)) != len(flat):
        raise ValueError("value_lrt needs one cell per (value, context) pair")
    out = np.empty(len(k))
    for lo in range(0, len(k), CHUNK):
        kg = np.zeros((min(CHUNK, len(k) - lo), n_values * n_contexts))
        ng = np.zeros_like(kg)
        kg[:, flat], ng[:, flat] = k[lo : lo + CHUNK], n[lo : lo + CHUNK]
        shape = (len(kg), n_values, n_contexts)
        out[lo : lo + CHUNK] = _grid_lrt(kg.reshape(shape), ng.reshape(shape))
    return out
