"""What a `lerobot_async` client has LeRobot's policy server load, and what it needs to know of it: read from the
checkpoint when it is a folder on this machine, else taken from the flags (the server loads it on its side)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from roboview.core.cli_errors import flag_errors
from roboview.policies.lerobot_policy import CHUNKED_TYPES, checkpoint_image_size, is_chunked, load_config
from roboview.sim.cameras import ALL_CAMERAS

# Policy types served here: chunked in-process (CHUNKED_TYPES) and known to lerobot's server
# (lerobot.async_inference.constants.SUPPORTED_POLICIES: act, smolvla, diffusion, tdmpc, vqbet, pi0, pi05, groot).
SERVED_TYPES = tuple(t for t in CHUNKED_TYPES if t in ("act", "smolvla", "pi0", "pi05"))


@dataclass(frozen=True)
class ServedCheckpoint:
    """A checkpoint as the server is told to load it and the client feeds it."""

    policy_type: str
    path: str  # as sent to the server
    actions_per_chunk: int
    cameras: tuple[str, ...]
    image_size: int


def resolve_checkpoint(
    path: str | None, policy_type: str, cameras: str, image_size: int, actions_per_chunk: int
) -> ServedCheckpoint:
    """The checkpoint `--policy.path` names, with the other flags' values (each 0 or empty: read from the
    checkpoint); ValueError naming the flag."""
    if not path:
        raise ValueError(
            "--policy.path: give the checkpoint as the server loads it (a pretrained_model folder "
            "or a hub id ORG/NAME)"
        )
    flag_cams = tuple(c.strip() for c in cameras.split(",") if c.strip())
    unknown = [c for c in flag_cams if c not in ALL_CAMERAS]
    if unknown:
        raise ValueError(
            f"--policy.cameras={cameras!r}: unknown camera(s) {unknown}; allowed: {', '.join(ALL_CAMERAS)}"
        )
    given = ServedCheckpoint(policy_type, path, actions_per_chunk, flag_cams, image_size)
    return _read_folder(given) if Path(path).exists() else _from_flags(given)


def _read_folder(given: ServedCheckpoint) -> ServedCheckpoint:
    """A checkpoint folder here: its type, absolute path, chunk length (unless given), cameras and image side; it
    must be served as it runs in-process, and the flags may only repeat what it says."""
    with flag_errors("--policy.path"):
        root, config = load_config(given.path)
        side = checkpoint_image_size(given.path)
    # The cameras the checkpoint reads (none for a state-only one; the env still renders `front`).
    cameras = tuple(
        k.removeprefix("observation.images.")
        for k in config.input_features
        if k.startswith("observation.images.")
    )
    kind = config.type
    per_chunk = given.actions_per_chunk or int(getattr(config, "n_action_steps", None) or config.chunk_size)
    if not is_chunked(config) or kind not in SERVED_TYPES:
        what = "an ACT checkpoint with temporal ensembling" if kind == "act" else f"a {kind!r} checkpoint"
        raise ValueError(
            f"--policy.path: {what} is not served as it runs in-process (LeRobot's server only "
            "calls predict_action_chunk: per-step state is lost); served: chunked "
            f"{', '.join(SERVED_TYPES)} checkpoints. Use --policy.type=lerobot"
        )
    chunk_size = getattr(config, "chunk_size", None)
    if chunk_size and per_chunk > chunk_size:
        raise ValueError(
            f"--policy.actions_per_chunk={per_chunk} exceeds the checkpoint's chunk_size {chunk_size}"
        )
    clashes = [
        f"--policy.{flag}={flag_value!r} but the checkpoint says {own!r}"
        for flag, flag_value, own in (
            ("policy_type", given.policy_type, kind),
            ("cameras", ",".join(given.cameras), ",".join(cameras)),
            ("image_size", given.image_size, side),
        )
        if flag_value and flag_value != own
    ]
    if clashes:
        raise ValueError(f"{'; '.join(clashes)} (drop the flag: a checkpoint folder here is read)")
    return ServedCheckpoint(kind, str(root.absolute()), per_chunk, cameras, int(side or 0))


def _from_flags(given: ServedCheckpoint) -> ServedCheckpoint:
    """A checkpoint not readable here (a folder on the server's machine, a hub id): every fact from its flag."""
    missing = [
        flag
        for flag, flag_value in (
            ("policy_type", given.policy_type),
            ("cameras", given.cameras),
            ("image_size", given.image_size),
            ("actions_per_chunk", given.actions_per_chunk),
        )
        if not flag_value
    ]
    if missing:
        raise ValueError(
            f"--policy.path={given.path!r} is not a folder on this machine (the server loads it on its "
            "side), so its cameras, image size, type and chunk length cannot be read here: pass "
            + " ".join(f"--policy.{flag}=…" for flag in missing)
            + " (e.g. --policy.cameras=left_top,wrist --policy.image_size=224 "
            "--policy.policy_type=act --policy.actions_per_chunk=50)"
        )
    if given.policy_type not in SERVED_TYPES:
        raise ValueError(
            f"--policy.policy_type={given.policy_type!r}: served types are {', '.join(SERVED_TYPES)}"
        )
    return given
