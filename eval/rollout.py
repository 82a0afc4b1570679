"""One evaluation episode, and the per-process worker that runs them (local pool or Ray actor).

A worker owns one env (one renderer) and one policy for its whole life. An episode is a pure
function of (policy, instance, repeat): its seed is `episode_seed(context_id, repeat)` (common random
numbers: every value of a context shares it), so every backend and machine produces the same row.
"""

from __future__ import annotations

import io
import logging
import os
import sys
import time
from dataclasses import dataclass

import numpy as np

from policies.base import Episode, PolicyConfig, TransientPolicyError, make_policy
from roboview_data.benchmark.format import BenchmarkItem
from roboview_data.sim.env import IMAGE_KEY
from roboview_data.sim.tasks import DEFAULT_TASK, load_task, make_env
from roboview_data.variation.instances import episode_seed

log = logging.getLogger(__name__)

# Policy calls that fail with these are retried (HTTP timeouts, dropped connections, rate limits);
# any other exception, or the last retry's, ends the episode as a failure with the error as reason.
TRANSIENT_ERRORS = (TimeoutError, ConnectionError, TransientPolicyError)
POLICY_RETRIES = 2
RETRY_BACKOFF_S = 0.5


class PolicyFailed(Exception):
    """A policy call raised: the episode is over, recorded as a failure with this reason."""


@dataclass(frozen=True)
class WorkerSpec:
    policy: PolicyConfig
    image_size: int = 224
    max_steps: int = 120
    # Keep compressed frames and trajectories for the Rerun recording.
    record_media: bool = False
    # Intra-op threads of a torch policy in this worker (cores / workers); 0 leaves torch's default.
    torch_threads: int = 0
    # The task of every instance this worker runs (roboview_data.sim.tasks).
    task: str = DEFAULT_TASK


@dataclass(frozen=True)
class WorkItem:
    item: BenchmarkItem
    repeat: int

    @property
    def key(self) -> tuple[str, int]:
        return self.item.record["instance_id"], self.repeat


@dataclass
class EpisodeResult:
    row: dict
    # Only with record_media: camera -> list of JPEG bytes; (T, 3) end-effector / object positions.
    frames: dict[str, list[bytes]] | None = None
    ee_path: np.ndarray | None = None
    object_path: np.ndarray | None = None


def _jpeg(image: np.ndarray) -> bytes:
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(image).save(buf, format="JPEG", quality=85)
    return buf.getvalue()


class EvalWorker:
    def __init__(self, spec: WorkerSpec) -> None:
        os.environ.setdefault("MUJOCO_GL", "egl")
        self.spec = spec
        self.env = make_env(spec.task, cameras=spec.policy.cameras(), image_size=spec.image_size,
                            max_steps=spec.max_steps, depth=spec.policy.depth)
        self.policy = make_policy(spec.policy, self.env)
        if spec.torch_threads and "torch" in sys.modules:  # a torch policy was loaded; eval/ names none
            sys.modules["torch"].set_num_threads(spec.torch_threads)

    def _call_policy(self, fn, *args):
        """fn(*args), retrying transient errors; any failure becomes PolicyFailed naming the error."""
        for attempt in range(POLICY_RETRIES + 1):
            try:
                return fn(*args)
            except TRANSIENT_ERRORS as exc:
                if attempt == POLICY_RETRIES:
                    raise PolicyFailed(f"policy error after {POLICY_RETRIES} retries: "
                                       f"{type(exc).__name__}: {exc}") from exc
                log.warning("policy %s raised %s (%s); retry %d/%d", fn.__name__, type(exc).__name__, exc,
                            attempt + 1, POLICY_RETRIES)
                time.sleep(RETRY_BACKOFF_S * 2**attempt)
            except Exception as exc:
                raise PolicyFailed(f"policy error: {type(exc).__name__}: {exc}") from exc

    def run(self, work: WorkItem) -> EpisodeResult:
        instance, record = work.item.instance, work.item.record
        seed = episode_seed(record["context_id"], work.repeat)
        start = time.perf_counter()
        obs, _ = self.env.reset(seed=seed, options={"instance": instance})
        media = self.spec.record_media
        frames: dict[str, list[bytes]] = {c: [] for c in self.env.cameras} if media else {}
        ee, obj = [], []
        success, info, error = False, {}, ""
        try:
            self._call_policy(self.policy.reset, Episode.of(self.env, seed))
            for _ in range(self.env.max_steps):
                if media:
                    for cam in self.env.cameras:
                        frames[cam].append(_jpeg(obs[IMAGE_KEY.format(cam)]))
                    ee.append(self.env.ee_position())
                    obj.append(self.env.object_pose()[0])
                action = np.asarray(self._call_policy(self.policy.select_action, obs), dtype=np.float32)
                if action.shape != self.env.action_space.shape or not np.all(np.isfinite(action)):
                    raise PolicyFailed(f"policy error: action of shape {action.shape} with values {action.ravel()[:8]} "
                                       f"(the env takes {self.env.action_space.shape[0]} finite values)")
                obs, _, success, truncated, info = self.env.step(action)
                if success or truncated:
                    break
        except PolicyFailed as exc:
            error = str(exc)
        reason = "" if success else (error or info.get("failure_reason") or getattr(self.policy, "failure_reason", "")
                                     or f"{load_task(self.spec.task).timeout_reason} within {self.env.max_steps} steps")
        row = {**record, "repeat": work.repeat, "episode_seed": seed, "success": bool(success),
               "steps": self.env.steps, "duration_s": time.perf_counter() - start,
               "policy": self.spec.policy.name or self.policy.name, "failure_reason": reason}
        extra = getattr(self.policy, "episode_record", None)
        if extra is not None:  # a policy's own columns (VLM usage, the refined instruction, ...)
            row |= {k: v for k, v in extra().items() if k not in row}
        if not media:
            return EpisodeResult(row)
        return EpisodeResult(row, frames, np.array(ee), np.array(obj))

    def close(self) -> None:
        close = getattr(self.policy, "close", None)
        if close is not None:
            close()
        self.env.close()
