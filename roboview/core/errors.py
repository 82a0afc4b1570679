"""Failures that are not the policy's: the evaluator records their episodes as ended by infrastructure."""

from __future__ import annotations


class InfraError(RuntimeError):
    """The episode was ended by infrastructure, not by the policy: raise it from `reset`/`select_action` when
    the policy's server was lost mid-episode (and reconnecting worked), an endpoint stayed out after its
    retries, or anything else outside the policy cut the episode short.

    The evaluator records such an episode with `status` `infra_error` (its reason in `failure_reason`); it is left
    out of every rate and test, and re-run later in the same invocation and by rerunning the same command. A
    failure of the policy itself — a bad output, an exception from its own code — is anything else.
    """


class RenderError(InfraError):
    """The simulator could not render a camera (a lost GL context, out of GPU memory): the episode is ended by
    infrastructure, not by the policy that was reading the image."""
