"""One evaluation episode, and the per-process worker that runs them (local pool or Ray actor).

A worker owns one env (one renderer) and one policy for its whole life. An episode is a pure
function of (policy, instance, repeat): its seed is `episode_seed(context_id, repeat)` (common random
numbers: every value of a context shares it), so every backend and machine produces the same row.

Every row has a `status`: `ok` when its outcome is the policy's (a success, or a failure of the policy itself:
its output, an exception from its own code, the step budget), `infra_error` when infrastructure ended it (an
`InfraError` such as a policy server lost mid-episode or a `RenderError`, a frame the policy was handed that cannot be
right (`roboview.eval.running.frames`: constant, or unchanged across a reset that moved the scene), a call still
failing with a transient error after `POLICY_RETRIES` retries, a worker that died: `lost_row`). Infra rows count in
no rate.
"""

from __future__ import annotations

import io
import logging
import os
import sys
import time
from dataclasses import dataclass, field

import numpy as np

from roboview.benchmark.format import BenchmarkItem
from roboview.core.workers import set_worker_rank
from roboview.eval.running import isolation
from roboview.eval.running.frames import FrameCheck
from roboview.eval.running.policy_server import RemotePolicy, ServerHandle
from roboview.eval.running.row import INFRA_ERROR, STATUS_OK, EpisodeRow
from roboview.policies.base import Episode, PolicyConfig, TransientPolicyError
from roboview.policies.errors import InfraError, PolicyUnavailable
from roboview.policies.factory import make_policy_batch
from roboview.tasks import DEFAULT_TASK, load_task, make_env
from roboview.tasks.env import IMAGE_KEY
from roboview.variation.instances import episode_seed

log = logging.getLogger(__name__)

# Policy calls that fail with these are retried (HTTP timeouts, dropped connections, rate limits); the last
# retry's failure ends the episode by infrastructure (an endpoint outage). Any other exception ends it as the
# policy's failure with the error as reason; an InfraError ends it by infrastructure at once.
TRANSIENT_ERRORS = (TimeoutError, ConnectionError, TransientPolicyError)
POLICY_RETRIES = 2
RETRY_BACKOFF_S = 0.5
# The `status` column of an episode row (roboview.eval.running.results reads it: `counted`).


class PolicyFailed(Exception):
    """A policy call raised: the episode is over, recorded as a failure with this reason (`infra`: ended by
    infrastructure, not by the policy)."""

    def __init__(self, reason: str, infra: bool = False) -> None:
        super().__init__(reason)
        self.infra = infra


@dataclass(frozen=True)
class WorkerSpec:
    policy: PolicyConfig
    image_size: int = 224
    # None: the env's own (LIBERO's: its suite's, set at every reset).
    max_steps: int | None = 120
    # Keep compressed frames and trajectories for the Rerun recording.
    record_media: bool = False
    # Intra-op threads of a torch policy in this worker (cores / workers); 0 leaves torch's default.
    torch_threads: int = 0
    # The task of every instance this worker runs (roboview.tasks).
    task: str = DEFAULT_TASK
    # Envs stepped in lockstep by this worker, the policy called once per step on their batch.
    envs_per_worker: int = 1
    # Videos (for work items that ask for one): keep them only for failed episodes.
    videos_of_failures_only: bool = False
    # Render observations eagerly (every camera, every step) instead of when read: for measurements only.
    eager: bool = False
    # Serve the policy from one server process shared by every worker (roboview.eval.running.policy_server); the backend
    # starts the server and fills in `server` for the workers it spawns.
    policy_server: bool = False
    server: ServerHandle | None = None


@dataclass(frozen=True)
class WorkItem:
    item: BenchmarkItem
    repeat: int
    # Keep the observed cameras' frames of this episode for its video (every camera rendered every step).
    video: bool = False

    @property
    def key(self) -> tuple[str, int]:
        return self.item.record["instance_id"], self.repeat


@dataclass
class EpisodeResult:
    row: dict
    # Only with record_media: camera -> list of JPEG bytes; (T, 3) end-effector / object positions; (T, A) the actions
    # the policy took (T − 1 of them when the episode ended on its last observation).
    frames: dict[str, list[bytes]] | None = None
    ee_path: np.ndarray | None = None
    object_path: np.ndarray | None = None
    actions: np.ndarray | None = None
    # Only for a work item with video: camera -> (T, H, W, 3) uint8, the frames the policy was shown.
    video: dict[str, np.ndarray] | None = None


def _infra_reason(exc: BaseException) -> str:
    """The failure_reason of an episode that infrastructure ended."""
    return f"infrastructure error: {type(exc).__name__}: {exc}"


def _infra_cause(exc: BaseException) -> InfraError | None:
    """The InfraError `exc` was raised from or while handling, if any."""
    seen: set[int] = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, InfraError):
            return exc
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return None


def _jpeg(image: np.ndarray) -> bytes:
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(image).save(buf, format="JPEG", quality=85)
    return buf.getvalue()


@dataclass
class _Running:
    """One episode in flight in one slot of a worker."""

    index: int
    work: WorkItem
    seed: int
    start: float
    obs: dict
    frames: dict[str, list[bytes]]
    video: dict[str, list[np.ndarray]]
    ee: list = field(default_factory=list)
    obj: list = field(default_factory=list)
    acts: list = field(default_factory=list)
    success: bool = False
    info: dict = field(default_factory=dict)
    error: str = ""
    # The error ended the episode by infrastructure (status infra_error), not by the policy.
    infra: bool = False
    # The isolation certificate's hashes (eval/running/isolation.py), taken right after the reset.
    isolation: str = ""

    def fail(self, reason: str, infra: bool) -> None:
        self.error, self.infra = reason, infra


class EvalWorker:
    """`envs_per_worker` envs (one renderer each) and one policy batch (one model) for a worker's life."""

    def __init__(self, spec: WorkerSpec, rank: int | None = None) -> None:
        os.environ.setdefault("MUJOCO_GL", "egl")
        if rank is not None:  # Ray actors are told their rank; pool workers take theirs at start
            set_worker_rank(rank)
        self.spec = spec
        task = load_task(spec.task)
        # A privileged policy reads the simulator's state, no image: it watches the world's own cameras (the videos).
        world_cameras = task.env_class().world.privileged_cameras
        cameras = (
            world_cameras if spec.policy.privileged and world_cameras else spec.policy.observed_cameras()
        )
        steps = {} if spec.max_steps is None else {"max_steps": spec.max_steps}
        self.envs = [
            make_env(
                spec.task,
                cameras=cameras,
                image_size=spec.image_size,
                depth=spec.policy.depth,
                lazy=not spec.eager,
                control=spec.policy.env_control(),
                **steps,
            )
            for _ in range(spec.envs_per_worker)
        ]
        self.batch = (
            RemotePolicy(spec.server)
            if spec.server is not None
            else make_policy_batch(spec.policy, self.envs)
        )
        self.env, self.policy = self.envs[0], self.batch.policy(0)
        self.frame_checks = [FrameCheck(env) for env in self.envs]
        if spec.torch_threads and "torch" in sys.modules:  # a torch policy was loaded; eval/ names none
            sys.modules["torch"].set_num_threads(spec.torch_threads)

    def _call_policy(self, fn, *args):
        """fn(*args), retrying transient errors; any failure becomes PolicyFailed naming the error (infra for an
        InfraError and for transient errors past the retries), except PolicyUnavailable (the policy's server is
        down), which stops the run."""
        for attempt in range(POLICY_RETRIES + 1):
            try:
                return fn(*args)
            except PolicyUnavailable:
                raise
            except InfraError as exc:
                raise PolicyFailed(_infra_reason(exc), infra=True) from exc
            except TRANSIENT_ERRORS as exc:
                if attempt == POLICY_RETRIES:
                    raise PolicyFailed(
                        f"policy error after {POLICY_RETRIES} retries: {type(exc).__name__}: {exc}",
                        infra=True,
                    ) from exc
                log.warning(
                    "policy %s raised %s (%s); retry %d/%d",
                    fn.__name__,
                    type(exc).__name__,
                    exc,
                    attempt + 1,
                    POLICY_RETRIES,
                )
                time.sleep(RETRY_BACKOFF_S * 2**attempt)
            except Exception as exc:
                cause = _infra_cause(exc)  # a policy that wrapped a render failure in its own error
                if cause is not None:
                    raise PolicyFailed(_infra_reason(cause), infra=True) from exc
                raise PolicyFailed(f"policy error: {type(exc).__name__}: {exc}") from exc

    def run(self, work: WorkItem) -> EpisodeResult:
        return self.run_batch([work])[0]

    def run_batch(self, works: list[WorkItem]) -> list[EpisodeResult]:
        """Every episode of `works` (results in that order), up to `envs_per_worker` of them in lockstep.

        A slot whose episode ends starts the next one at once. An episode is a function of (policy, instance,
        repeat) alone: its env is reset with the episode seed and its policy slot told the episode, whichever
        slot runs it and whoever runs beside it (batched inference aside: see `make_policy_batch`).
        """
        queue = list(enumerate(works))[::-1]
        results: list[EpisodeResult | None] = [None] * len(works)
        running: dict[int, _Running] = {}
        while queue or running:
            for slot in range(len(self.envs)):
                if slot not in running and queue:
                    running[slot] = self._start(slot, *queue.pop())
            for slot, ep in running.items():
                if not ep.error:
                    self._guarded(ep, self._record, slot, ep)
            acting = {slot: ep for slot, ep in running.items() if not ep.error}
            actions = self._actions(acting)
            for slot, ep in acting.items():  # what the policy was shown, even where it then failed
                if not ep.infra:
                    self._guarded(ep, self.frame_checks[slot].check, ep.obs)
            for slot, ep in list(running.items()):
                if not ep.error:
                    self._guarded(ep, self._step, slot, ep, actions[slot])
                env = self.envs[slot]
                if ep.error or ep.success or env.steps >= env.max_steps or ep.info.get("failure_reason"):
                    results[ep.index] = self._finish(slot, running.pop(slot))
        return results  # type: ignore[return-value]

    @staticmethod
    def _guarded(ep: _Running, fn, *args) -> None:
        """fn(*args); an InfraError it raises (a camera that failed to render) ends `ep` by infrastructure."""
        try:
            fn(*args)
        except InfraError as exc:
            ep.fail(_infra_reason(exc), infra=True)

    def _start(self, slot: int, index: int, work: WorkItem) -> _Running:
        env = self.envs[slot]
        instance, record = work.item.episode(work.repeat), work.item.record
        seed = episode_seed(record["context_id"], work.repeat)
        start = time.perf_counter()
        ep = _Running(
            index,
            work,
            seed,
            start,
            {},
            {c: [] for c in env.cameras} if self.spec.record_media else {},
            {c: [] for c in env.cameras} if work.video else {},
        )
        try:
            ep.obs, _ = env.reset(seed=seed, options={"instance": instance})
        except InfraError as exc:  # an eager env renders in its reset
            ep.fail(_infra_reason(exc), infra=True)
            return ep
        ep.isolation = isolation.record(env, seed)
        self.frame_checks[slot].new_episode()
        try:
            self._call_policy(self.batch.reset, slot, Episode.of(env, seed))
        except PolicyFailed as exc:
            ep.fail(str(exc), exc.infra)
        return ep

    def _record(self, slot: int, ep: _Running) -> None:
        env = self.envs[slot]
        if self.spec.record_media:
            for cam in env.cameras:
                ep.frames[cam].append(_jpeg(ep.obs[IMAGE_KEY.format(cam)]))
            ep.ee.append(env.ee_position())
            ep.obj.append(env.object_pose()[0])
        for cam in ep.video:
            ep.video[cam].append(ep.obs[IMAGE_KEY.format(cam)])

    def _actions(self, acting: dict[int, _Running]) -> dict[int, np.ndarray]:
        """One action per acting slot: one policy call for the batch, or one per slot (a failure ends only
        the episodes of the call that failed)."""
        groups = [list(acting)] if self.batch.batched else [[slot] for slot in acting]
        actions: dict[int, np.ndarray] = {}
        for group in groups:
            try:
                actions |= self._call_policy(self.batch.select_actions, {s: acting[s].obs for s in group})
            except PolicyFailed as exc:
                for slot in group:
                    acting[slot].fail(str(exc), exc.infra)
        return actions

    def _step(self, slot: int, ep: _Running, action) -> None:
        env = self.envs[slot]
        action = np.asarray(action, dtype=np.float32)
        if action.shape != env.action_space.shape or not np.all(np.isfinite(action)):
            ep.error = (
                f"policy error: action of shape {action.shape} with values {action.ravel()[:8]} "
                f"(the env takes {env.action_space.shape[0]} finite values)"
            )
            return
        if self.spec.record_media:
            ep.acts.append(action)
        ep.obs, _, ep.success, _, ep.info = env.step(action)

    def _finish(self, slot: int, ep: _Running) -> EpisodeResult:
        env, record = self.envs[slot], ep.work.item.record
        reason = (
            ""
            if ep.success
            else (
                ep.error
                or ep.info.get("failure_reason")
                or self.batch.failure_reason(slot)
                or load_task(self.spec.task).timeout_failure(env.max_steps)
            )
        )
        row = EpisodeRow(
            record,
            repeat=ep.work.repeat,
            episode_seed=ep.seed,
            success=bool(ep.success),
            steps=env.steps,
            duration_s=time.perf_counter() - ep.start,
            policy=self.spec.policy.name or self.batch.name,
            failure_reason=reason,
            unit=ep.work.item.repetition.unit(ep.work.item.instance, ep.work.repeat),
            isolation=ep.isolation,
            status=INFRA_ERROR if ep.infra else STATUS_OK,
            extra=self.batch.episode_record(
                slot
            ),  # a policy's own columns (VLM usage, the refined instruction, ...)
        ).as_dict()
        result = EpisodeResult(row)
        if self.spec.record_media:
            result.frames, result.ee_path, result.object_path = ep.frames, np.array(ep.ee), np.array(ep.obj)
            result.actions = np.array(ep.acts)
        if ep.video and not ep.infra and not (self.spec.videos_of_failures_only and ep.success):
            try:
                for cam in ep.video:  # and the last observation: how the episode ended
                    ep.video[cam].append(ep.obs[IMAGE_KEY.format(cam)])
            except InfraError as exc:  # the outcome stands; the video ends a frame early
                log.warning("episode %s repeat %d: last video frame not rendered (%s)", *ep.work.key, exc)
            result.video = {cam: np.stack(frames) for cam, frames in ep.video.items() if frames}
        return result

    def close(self) -> None:
        self.batch.close()
        for env in self.envs:
            env.close()


def lost_row(work: WorkItem, reason: str, policy: str | None) -> dict:
    """The row of an episode whose worker died (no worker is left to say more): status infra_error, `policy`
    the run's policy name where known (else None: the evaluator fills it in)."""
    record = work.item.record
    return EpisodeRow(
        record,
        repeat=work.repeat,
        episode_seed=episode_seed(record["context_id"], work.repeat),
        success=False,
        steps=0,
        duration_s=0.0,
        policy=policy,
        failure_reason=reason,
        unit=work.item.repetition.unit(work.item.instance, work.repeat),
        status=INFRA_ERROR,
    ).as_dict()
