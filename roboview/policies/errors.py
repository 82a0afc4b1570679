"""Errors a policy (or the simulator) raises to tell the evaluator what kind of failure it met."""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

# Infrastructure failures live on the lowest floor (the simulator raises RenderError); part of the policy API.
from roboview.core.errors import InfraError, RenderError  # noqa: F401

log = logging.getLogger(__name__)


class TransientPolicyError(RuntimeError):
    """A failure worth retrying (an HTTP timeout, a rate limit): raise it from `select_action`/`reset`.

    The evaluator retries such calls a few times (as it does `TimeoutError` and `ConnectionError`); one still
    failing after that ended its episode by infrastructure (an endpoint outage: `status` `infra_error`, not
    counted). Any other exception ends the episode as the policy's failure, recording the error as its reason.
    """


class PolicyUnavailable(RuntimeError):
    """The policy cannot be reached at all (its server is down and reconnecting failed): raise it from
    `reset`/`select_action` to stop the run instead of failing episode after episode.

    Episodes already finished stay written; the message should name what is down and say that rerunning
    the same command resumes once it is back. (A server's error frame while an episode runs is that episode's
    failure: raise anything else; a connection lost mid-episode and reopened is an `InfraError`.)
    """


def open_with_retries[T](
    open_fn: Callable[[], T],
    server: str,
    reconnects: int,
    backoff_s: float,
    lost: str = "",
    retry_on: tuple[type[BaseException], ...] = (Exception,),
    flag: str = "--policy.url",
) -> T:
    """`open_fn()` (a served policy's connection), tried `reconnects` more times on `retry_on` errors, `backoff_s`
    apart and doubling; `PolicyUnavailable` naming `server` (and what was `lost`) when every try fails. The one
    retry loop of every served policy (openpi, vla_eval, lerobot_async); any other error propagates at once."""
    last: BaseException | None = None
    for attempt in range(reconnects + 1):
        try:
            return open_fn()
        except retry_on as exc:  # refused, timed out, bad handshake
            last = exc
            log.warning("%s unreachable (%s); attempt %d/%d", server, exc, attempt + 1, reconnects + 1)
            if attempt < reconnects:
                time.sleep(backoff_s * 2**attempt)
    raise PolicyUnavailable(
        f"{server} is unreachable after {reconnects + 1} attempts ({lost + '; ' if lost else ''}"
        f"{type(last).__name__}: {last}); start it (or fix {flag}) and rerun the same command: finished "
        "episodes are kept and the run resumes"
    )
