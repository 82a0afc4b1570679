"""Errors a policy raises to tell the evaluator what kind of failure it met."""

from __future__ import annotations


class TransientPolicyError(RuntimeError):
    """A failure worth retrying (an HTTP timeout, a rate limit): raise it from `select_action`/`reset`.

    The evaluator retries such calls a few times (as it does `TimeoutError` and `ConnectionError`);
    any other exception ends the episode as a failure recording the error as its reason.
    """


class PolicyUnavailable(RuntimeError):
    """The policy cannot be reached at all (its server is down and reconnecting failed): raise it from
    `reset`/`select_action` to stop the run instead of failing episode after episode.

    Episodes already finished stay written; the message should name what is down and say that rerunning
    the same command resumes once it is back. (An error while an episode runs — a server's error frame, a
    connection closed mid-episode — is that episode's failure: raise anything else.)
    """
