"""Errors a policy raises to tell the evaluator what kind of failure it met."""

from __future__ import annotations


class TransientPolicyError(RuntimeError):
    """A failure worth retrying (an HTTP timeout, a rate limit): raise it from `select_action`/`reset`.

    The evaluator retries such calls a few times (as it does `TimeoutError` and `ConnectionError`);
    any other exception ends the episode as a failure recording the error as its reason.
    """
