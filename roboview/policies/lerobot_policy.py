"""Any LeRobot policy checkpoint (ACT, Diffusion, π0, SmolVLA, …) as a RoboView policy.

Loaded the way `lerobot-eval` loads it: the config and weights through the policy class's
`from_pretrained`, and the checkpoint's own saved pre/post-processors (normalization, device,
tokenization). Our observation keys are the dataset's feature keys, so a policy trained on
`roboview.pipelines.collect` demos needs no renaming; a checkpoint that wants a camera or a state/action
shape this env cannot provide fails before any rollout with the mismatch spelled out.

The control mode comes from the checkpoint: an 8-d action is joint targets; a 7-d one is end-effector
control, ee_delta or ee_abs as the training dataset's `action` names say (read from the dataset that
`train_config.json` names). An EE checkpoint gets the env's `observation.ee_state` as its
`observation.state`, as its dataset recorded it.
"""

from __future__ import annotations

import collections
import copy
import functools
import json
import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from roboview.core.cli_errors import flag_errors
from roboview.policies.base import AgentView, Episode, PolicyConfig, control_field
from roboview.policies.checkpoints import CheckpointError, checkpoint_dir
from roboview.policies.devices import resolve_device
from roboview.sim.control import CONTROLS, EE_ACTION_NAMES, EE_CONTROLS
from roboview.tasks import camera_names
from roboview.tasks.base import control_of_action_names, feature_dims
from roboview.tasks.env import EE_STATE_KEY, IMAGE_KEY, STATE_KEY
from roboview.tasks.world import camera_of_feature

log = logging.getLogger(__name__)


@functools.lru_cache(maxsize=8)
def _read_config(root: Path):
    import lerobot.policies  # noqa: F401  (registers every policy config type: act, diffusion, pi0, …)
    from lerobot.configs.policies import PreTrainedConfig

    try:
        config = PreTrainedConfig.from_pretrained(root)
    except Exception as exc:  # draccus/json errors: say which file
        raise CheckpointError(f"cannot read {root / 'config.json'}: {exc}") from exc
    check_features(config)
    return config


def load_config(path: str | None):
    """(checkpoint folder, a fresh copy of its config); config.json is parsed and checked once per process."""
    root = checkpoint_dir(path)
    return root, copy.deepcopy(_read_config(root))


def check_features(config) -> None:
    """Every input the checkpoint wants must be one some world renders; its state and action widths must be some
    world's in some control (roboview.tasks.base.feature_dims)."""
    problems = []
    cameras = camera_names()
    dims = feature_dims()
    state_widths = sorted({s for _, s, _ in dims})
    action_widths = sorted({a for _, _, a in dims})
    for key, feature in config.input_features.items():
        cam = camera_of_feature(key)
        if cam is not None:
            if cam not in cameras:
                problems.append(f"camera {cam!r} (the envs' cameras: {', '.join(cameras)})")
        elif key == STATE_KEY:
            if tuple(feature.shape)[-1:] not in [(w,) for w in state_widths]:
                problems.append(
                    f"{key} shape {tuple(feature.shape)} (the envs' states: widths {state_widths})"
                )
        else:
            problems.append(f"input {key!r} (env provides observation.images.<camera> and {STATE_KEY})")
    action = config.output_features.get("action")
    if action is None or tuple(action.shape) not in [(w,) for w in action_widths]:
        shape = None if action is None else tuple(action.shape)
        widths = ", ".join(f"({a},): {c}" for c, _, a in dims)
        problems.append(f"action shape {shape} (the envs' actions: {widths})")
    if problems:
        raise CheckpointError("checkpoint does not match RoboView's envs: " + "; ".join(problems))


EE_ACTION_DIMS = len(EE_ACTION_NAMES[EE_CONTROLS[0]])  # every EE control: 3 + 3 + gripper


def dataset_action_names(root: Path) -> list[str] | None:
    """The `action` feature names of the dataset a checkpoint was trained on (its `train_config.json` names the
    dataset: a local root, or a repo id in LeRobot's cache); None when that dataset cannot be read here."""
    train_config = root / "train_config.json"
    if not train_config.is_file():
        return None
    dataset = json.loads(train_config.read_text()).get("dataset") or {}
    candidates = []
    if dataset.get("root"):
        candidates.append(Path(dataset["root"]))
    if dataset.get("repo_id"):
        from lerobot.utils.constants import HF_LEROBOT_HOME

        candidates.append(Path(HF_LEROBOT_HOME) / str(dataset["repo_id"]))
    for candidate in candidates:
        info = candidate / "meta" / "info.json"
        if info.is_file():
            names = json.loads(info.read_text()).get("features", {}).get("action", {}).get("names")
            if (
                isinstance(names, dict) and len(names) == 1
            ):  # {"motors": [...]}, as LIBERO's datasets write it
                names = next(iter(names.values()))
            return list(names) if isinstance(names, list) else None
    return None


def refuse_control(path: str, given: str, found: str | None, fix: str) -> None:
    """Refuse `--policy.control=given` for a checkpoint that acts in `found` (None: an end-effector control its
    dataset does not name), ending the message with `fix`; nothing when the control fits."""
    if found is not None and given != found:
        raise ValueError(
            f"--policy.control={given!r} but the checkpoint {path} acts in {found!r} (its action shape and its "
            f"dataset's action names); {fix}"
        )
    if found is None and given == "joint":
        raise ValueError(
            f"--policy.control='joint' but the checkpoint {path} has a 7-d (end-effector) action; {fix}"
        )


def checkpoint_control(path: str | None) -> str | None:
    """The control a checkpoint acts in: the one whose action width it has, where only one control has it (joint:
    8-d; Meta-World's xyz_delta: 4-d); for a 7-d one the EE control whose action names its training dataset records
    (None when that dataset cannot be read here)."""
    root, config = load_config(path)
    width = tuple(config.output_features["action"].shape)[-1]
    controls = list(dict.fromkeys(c for c, _, a in feature_dims() if a == width))
    if len(controls) == 1:
        return controls[0]
    names = dataset_action_names(root)
    # The world whose datasets name their actions so (LeRobot-format LIBERO datasets: OSC_POSE deltas, ee_delta).
    return control_of_action_names(names) if names else None


def checkpoint_image_size(path: str | None) -> int | None:
    """The side of the checkpoint's (square) input images; every camera must share it."""
    _, config = load_config(path)
    shapes = {k: tuple(f.shape) for k, f in config.input_features.items() if camera_of_feature(k)}
    sides = {shape[-1] for shape in shapes.values()}
    if any(shape[-1] != shape[-2] for shape in shapes.values()) or len(sides) > 1:
        raise CheckpointError(
            f"checkpoint image shapes {shapes}: the env renders every camera as one square "
            "size; retrain on a dataset collected with --dataset.image_size=N"
        )
    return sides.pop() if sides else None


def checkpoint_cameras(path: str | None) -> tuple[str, ...]:
    _, config = load_config(path)
    cams = tuple(c for c in map(camera_of_feature, config.input_features) if c)
    return cams or ("front",)


# Policy types whose `select_action` is "predict a chunk when the queue is empty, then pop": for these the
# adapter keeps the queue itself and builds (renders) the observation only when a chunk is predicted, which
# is what lerobot's own `select_action` computes. Other types (diffusion's observation history, temporal
# ensembling) read every step's observation.
CHUNKED_TYPES = ("act", "pi0", "pi05", "smolvla", "xvla")


def is_chunked(config) -> bool:
    """Whether a checkpoint config runs as 'predict a chunk, pop it' (and so can be batched and served)."""
    return config.type in CHUNKED_TYPES and getattr(config, "temporal_ensemble_coeff", None) is None


class LeRobotPolicy:
    """A checkpoint driving one env, or `slots` envs in lockstep with one model (batched inference).

    Each slot has its own episode (instruction, action queue); `select_actions` predicts, in one forward
    pass, a chunk for every slot whose queue is empty and pops one action per slot.
    """

    failure_reason = ""

    def __init__(self, path: str, device: str, slots: int = 1, control: str = "joint") -> None:
        import torch
        from lerobot.policies.factory import get_policy_class, make_pre_post_processors

        root, config = load_config(path)
        device = resolve_device(device)
        config.device = device
        self.name = f"lerobot:{config.type}"
        self._torch = torch
        self.policy = get_policy_class(config.type).from_pretrained(root, config=config)
        self.policy.eval()
        self.preprocessor, self.postprocessor = make_pre_post_processors(
            policy_cfg=config,
            pretrained_path=str(root),
            preprocessor_overrides={"device_processor": {"device": device}},
        )
        # (checkpoint feature, env observation key) of every camera it reads.
        self.image_keys = [
            (k, IMAGE_KEY.format(camera_of_feature(k))) for k in config.input_features if camera_of_feature(k)
        ]
        # An end-effector checkpoint was trained on the EE state as its observation.state.
        self.state_key = STATE_KEY if control == "joint" else EE_STATE_KEY
        # Chunked: the adapter pops the chunk itself (observations read once per chunk, slots batched).
        self.chunked = is_chunked(config) and hasattr(self.policy, "predict_action_chunk")
        self.n_action_steps = int(getattr(config, "n_action_steps", 1))
        if slots > 1 and not self.chunked:
            raise ValueError(
                f"batched inference needs a chunked policy ({', '.join(CHUNKED_TYPES)} without temporal "
                f"ensembling); {config.type!r} keeps per-episode observation state: use envs_per_worker=1"
            )
        self.slots = slots
        self.tasks = [""] * slots
        # post-processed actions
        self.queues: list[collections.deque] = [collections.deque() for _ in range(slots)]
        self.reads = 0  # observations turned into model input (chunks predicted, per slot)

    def reset(self, episode: Episode, slot: int = 0) -> None:
        if not self.chunked:
            self.policy.reset()  # clears lerobot's own queues
        self.queues[slot].clear()
        self.tasks[slot] = episode.instruction
        # Policy randomness (diffusion noise, sampled latents) from the episode seed: common random
        # numbers cover the policy too, so two values of one (context, repeat) see the same draws.
        self._torch.manual_seed(episode.seed)

    def _batch(self, observations: list[dict], tasks: list[str]) -> dict:
        torch = self._torch
        batch = {
            STATE_KEY: torch.from_numpy(np.stack([o[self.state_key] for o in observations])).float(),
            "task": tasks,
        }
        for key, observed in self.image_keys:
            images = np.stack([o[observed] for o in observations])
            batch[key] = torch.from_numpy(images).permute(0, 3, 1, 2).float().div_(255.0)
        self.reads += len(observations)
        return self.preprocessor(batch)

    def select_action(self, observation: dict) -> np.ndarray:
        return self.select_actions({0: observation})[0]

    def select_actions(self, observations: dict[int, dict]) -> dict[int, np.ndarray]:
        """One action per slot in `observations` (slot -> that env's observation at this step)."""
        torch = self._torch
        if not self.chunked:
            ((slot, observation),) = observations.items()
            with torch.inference_mode():
                action = self.policy.select_action(self._batch([observation], [self.tasks[slot]]))
            return {slot: self._postprocess(action)}
        empty = [slot for slot in observations if not self.queues[slot]]
        if empty:
            for slot, actions in self.predict_chunks({s: observations[s] for s in empty}).items():
                self.queues[slot].extend(actions)
        return {slot: self.queues[slot].popleft() for slot in observations}

    def predict_chunks(
        self, observations: dict[int, dict], instructions: dict[int, str] | None = None
    ) -> dict[int, list[np.ndarray]]:
        """One forward pass over `observations` (slot -> observation): each slot's next `n_action_steps`
        actions, post-processed (what lerobot's `select_action` would pop one at a time). Each slot's
        instruction is its episode's, or the one given (a server's request carries its own)."""
        torch = self._torch
        slots = list(observations)
        tasks = [(instructions or {}).get(s, self.tasks[s]) for s in slots]
        batch = self._batch([observations[s] for s in slots], tasks)
        with torch.inference_mode():
            chunk = self.policy.predict_action_chunk(batch)[:, : self.n_action_steps]
        # One post-processor call for the whole (slots, steps, action) chunk: unnormalization is elementwise,
        # so this is bit for bit what post-processing each action alone gives.
        actions = self.postprocessor(chunk).cpu().numpy().astype(np.float32)
        return {slot: list(actions[row]) for row, slot in enumerate(slots)}

    def _postprocess(self, action) -> np.ndarray:
        return self.postprocessor(action).squeeze(0).cpu().numpy().astype(np.float32)

    def close(self) -> None:
        del self.policy, self.preprocessor, self.postprocessor


@PolicyConfig.register_subclass("lerobot")
@dataclass
class LeRobotConfig(PolicyConfig):
    """A LeRobot checkpoint: its cameras and image size are read from the checkpoint itself."""

    # Checkpoint folder (a lerobot-train `pretrained_model` folder, or the checkpoint folder holding one).
    path: str | None = None
    # Device: auto (CUDA when present), cpu or cuda.
    device: str = "auto"
    # Control mode: empty to read it from the checkpoint (8-d action: joint; 7-d: ee_delta or ee_abs, from its
    # training dataset's action names, else the one EE control the benchmark's envs take — LIBERO's: ee_delta);
    # name it (ee_delta / ee_abs) for a 7-d checkpoint on RoboView's scene whose dataset is not here.
    control: str = ""

    doc = "any LeRobot checkpoint (--policy.path=DIR)"
    row_name = "lerobot:*"  # lerobot:<the checkpoint's policy type>

    def worker_imports(self) -> tuple[str, ...]:
        return (*super().worker_imports(), "lerobot.policies")  # LeRobot's policies: seconds to import

    def __post_init__(self) -> None:
        with flag_errors("--policy.path"):
            load_config(self.path)  # missing or mismatched checkpoints fail before any rollout
        with flag_errors(f"--policy.device={self.device!r}"):
            resolve_device(self.device)
        self._resolve_control()
        super().__post_init__()

    def _resolve_control(self) -> None:
        given = self.control
        if given and given not in CONTROLS:
            raise ValueError(f"unknown --policy.control={given!r}; allowed: {', '.join(CONTROLS)}")
        found = checkpoint_control(self.path)
        if given:
            refuse_control(self.path, given, found, "drop the flag")
        self.control = given or found or ""  # "": open until the run's envs settle it (settle_control)
        if self.control:
            control_field(self)

    def settle_control(self, controls: tuple[str, ...]) -> None:
        ee = [c for c in controls if c in EE_CONTROLS]
        if not self.control and len(ee) == 1:
            self.control = ee[0]

    @property
    def checkpoint(self) -> str | None:
        return self.path

    def env_control(self) -> str:
        if not self.control:
            raise ValueError(
                f"the checkpoint {self.path} acts in end-effector space (7-d action) but its training dataset "
                f"(named in train_config.json) is not here to say which control: pass --policy.control="
                f"{' or --policy.control='.join(EE_CONTROLS)}"
            )
        return self.control

    def observed_cameras(self) -> tuple[str, ...]:
        return checkpoint_cameras(self.path)

    def input_image_size(self) -> int | None:
        return checkpoint_image_size(self.path)

    def build(self, view: AgentView) -> LeRobotPolicy:
        return LeRobotPolicy(self.path, self.device, control=self.env_control())

    def batchable(self) -> bool:
        return is_chunked(load_config(self.path)[1])

    def build_batched(self, view: AgentView, slots: int) -> LeRobotPolicy | None:
        if not self.batchable():
            log.warning(
                "%s keeps per-episode observation state: one model copy per env instead of a batch",
                load_config(self.path)[1].type,
            )
            return None
        return LeRobotPolicy(self.path, self.device, slots, control=self.env_control())
