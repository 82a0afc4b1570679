"""openpi's wire format as RoboView speaks it, shared by the client (`--policy.type=openpi`) and the batching
server (`roboview-serve-policy`): the observation layouts (`--policy.obs_format`: droid, libero, aloha,
custom key maps), what a request carries and what an answer must hold, and the episode message RoboView's
client sends with an episode's first request. The codec itself is openpi-client's `msgpack_numpy`."""

from __future__ import annotations

import logging
import re
from dataclasses import dataclass
from typing import Any

import numpy as np

from roboview.policies.base import Episode
from roboview.sim.control import EE_ACTION_NAMES
from roboview.tasks import camera_names
from roboview.tasks.env import ACTION_NAMES, DEPTH_KEY, IMAGE_KEY, STATE_KEY, STATE_NAMES
from roboview.tasks.world import wrist_camera_names

log = logging.getLogger(__name__)

OBS_FORMATS = ("droid", "libero", "aloha", "custom")
ACTION_SPACES = ("joint_position", "joint_velocity")
GRIPPER_MODES = ("continuous", "binary")
# RoboView's own server advertises itself under this metadata key; its clients then send the episode's
# details (task, seed, camera calibration) under EPISODE_KEY with each new episode's first request.
ROBOVIEW_KEY = "roboview"
EPISODE_KEY = "roboview/episode"
WIRE_DIMS = len(ACTION_NAMES)  # 7 joints + gripper
EE_WIRE_DIMS = len(EE_ACTION_NAMES["ee_delta"])  # end-effector pose (6) + gripper
# The wrist cameras by name, every world's (RoboView's `wrist`; LIBERO's `wrist` and `image2`, LeRobot's name of it).
WRIST_CAMERAS = wrist_camera_names()
_SLICE = re.compile(r"^state\[(\d*):(\d*)\]$")


class ProtocolError(RuntimeError):
    """The server answered something that is not a usable action chunk (fails that episode)."""


# ---------------------------------------------------------------------------------------------------------------
# Wire formats: RoboView observation <-> openpi request


@dataclass(frozen=True)
class WireFormat:
    """Where each part of a RoboView observation goes in a request: (wire path, source) pairs.

    A wire path is a tuple of keys (ALOHA nests its images under "images"); a source is `camera:NAME`,
    `camera_chw:NAME`, `depth:NAME`, `state[i:j]` or `instruction`."""

    name: str
    entries: tuple[tuple[tuple[str, ...], str], ...]

    @property
    def cameras(self) -> tuple[str, ...]:
        return tuple(
            dict.fromkeys(
                src.split(":", 1)[1] for _, src in self.entries if src.startswith(("camera:", "camera_chw:"))
            )
        )

    @property
    def depth_cameras(self) -> tuple[str, ...]:
        return tuple(src.split(":", 1)[1] for _, src in self.entries if src.startswith("depth:"))

    def encode(self, observation: dict, instruction: str, state_key: str = STATE_KEY) -> dict:
        """The request for one observation (only the cameras named are read, so only those render); `state`
        sources read `state_key` (the EE state for an end-effector control)."""
        request: dict[str, Any] = {}
        for path, src in self.entries:
            node = request
            for key in path[:-1]:
                node = node.setdefault(key, {})
            node[path[-1]] = _read(observation, src, instruction, state_key)
        return request

    def decode(
        self, request: dict, image_size: int, state_key: str = STATE_KEY, state_width: int = len(STATE_NAMES)
    ) -> tuple[dict, str]:
        """(RoboView observation, instruction) from a request; a missing key or a wrong image size is named. The
        state (`state_width` entries: the env's) goes under `state_key` (the EE state's key for a policy acting in
        an end-effector control)."""
        obs: dict[str, np.ndarray] = {}
        state = np.full(state_width, np.nan, np.float32)
        instruction = ""
        for path, src in self.entries:
            node: Any = request
            for key in path:
                if not isinstance(node, dict) or key not in node:
                    raise ValueError(
                        f"request has no {'/'.join(path)!r} ({self.name} layout); keys: {sorted(request)}"
                    )
                node = node[key]
            if src == "instruction":
                instruction = str(node)
            elif src.startswith("state"):
                lo, hi = _state_range(src, state_width)
                state[lo:hi] = np.asarray(node, np.float32).reshape(-1)
            else:
                kind, cam = src.split(":", 1)
                array = np.asarray(node)
                if kind == "camera_chw":
                    array = array.transpose(1, 2, 0)
                expected = (image_size, image_size, 3) if kind != "depth" else (image_size, image_size)
                if array.shape != expected:
                    raise ValueError(
                        f"{'/'.join(path)} has shape {array.shape}; this server's policy takes "
                        f"{expected} (images are not resized: render them at {image_size}²)"
                    )
                key = DEPTH_KEY.format(cam) if kind == "depth" else IMAGE_KEY.format(cam)
                obs[key] = array.astype(np.float32 if kind == "depth" else np.uint8, copy=False)
        if np.isnan(state).any():
            raise ValueError(
                f"the {self.name} layout leaves state entries {np.flatnonzero(np.isnan(state)).tolist()} "
                f"unset (the env's state has {state_width})"
            )
        obs[state_key] = state
        return obs, instruction


def _state_range(src: str, width: int) -> tuple[int, int]:
    if src == "state":
        return 0, width
    match = _SLICE.match(src)
    lo, hi = int(match.group(1) or 0), int(match.group(2) or width)
    return lo, hi


def _read(observation: dict, src: str, instruction: str, state_key: str = STATE_KEY):
    if src == "instruction":
        return instruction
    if src.startswith("state"):
        state = np.asarray(observation[state_key], np.float32)
        lo, hi = _state_range(src, len(state))
        return state[lo:hi].copy()
    kind, cam = src.split(":", 1)
    if kind == "depth":
        return np.ascontiguousarray(observation[DEPTH_KEY.format(cam)], np.float32)
    image = np.asarray(observation[IMAGE_KEY.format(cam)], np.uint8)
    return np.ascontiguousarray(image.transpose(2, 0, 1) if kind == "camera_chw" else image)


def parse_key_map(text: str) -> tuple[tuple[tuple[str, ...], str], ...]:
    """`wire_key=SOURCE,…` (custom layout) → entries; every source checked, errors name the entry."""
    entries = []
    for item in filter(None, (x.strip() for x in text.split(","))):
        wire, sep, src = item.partition("=")
        wire, src = wire.strip(), src.strip()
        if not sep or not wire or not src:
            raise ValueError(f"--policy.key_map entry {item!r} must be wire_key=SOURCE")
        if src.startswith(("camera:", "camera_chw:", "depth:")):
            cam = src.split(":", 1)[1]
            if cam not in camera_names():
                raise ValueError(
                    f"--policy.key_map entry {item!r}: unknown camera {cam!r}; "
                    f"allowed: {', '.join(camera_names())}"
                )
        elif src.startswith("state"):
            match = _SLICE.match(src)
            if src != "state" and (
                match is None or not (0 <= int(match.group(1) or 0) < int(match.group(2) or 8) <= 8)
            ):
                raise ValueError(
                    f"--policy.key_map entry {item!r}: state slices are state[i:j] with "
                    f"0 ≤ i < j ≤ {len(STATE_NAMES)} ({', '.join(STATE_NAMES)})"
                )
        elif src != "instruction":
            raise ValueError(
                f"--policy.key_map entry {item!r}: unknown source {src!r}; allowed: camera:NAME, "
                "camera_chw:NAME, depth:NAME, state, state[i:j], instruction"
            )
        entries.append(((wire,), src))
    if not entries:
        raise ValueError(
            "--policy.obs_format=custom needs --policy.key_map='wire_key=SOURCE,…' (e.g. "
            "'observation/image=camera:left_top,observation/state=state[0:8],prompt=instruction')"
        )
    return tuple(entries)


def wire_format(
    obs_format: str, cameras: tuple[str, ...], key_map: str = "", depth: bool = False
) -> WireFormat:
    """The layout `obs_format` for these cameras (scene cameras in order, then the wrist)."""
    if obs_format not in OBS_FORMATS:
        raise ValueError(f"unknown --policy.obs_format={obs_format!r}; allowed: {', '.join(OBS_FORMATS)}")
    if obs_format == "custom":
        return WireFormat("custom", parse_key_map(key_map))
    scene = [c for c in cameras if c not in WRIST_CAMERAS]
    wrist = next((c for c in cameras if c in WRIST_CAMERAS), None)
    if not scene:
        raise ValueError(
            f"--policy.obs_format={obs_format} needs a scene camera among --policy.cameras "
            f"(got {','.join(cameras)}; scene cameras: "
            f"{', '.join(c for c in camera_names() if c not in WRIST_CAMERAS)})"
        )
    limit = {"droid": 2, "libero": 1, "aloha": 2}[obs_format]
    if len(scene) > limit:
        raise ValueError(
            f"--policy.obs_format={obs_format} carries {limit} scene camera(s), got {', '.join(scene)}"
        )
    entries: list[tuple[tuple[str, ...], str]] = []
    if obs_format == "droid":
        entries += [(("observation/exterior_image_1_left",), f"camera:{scene[0]}")]
        if len(scene) > 1:
            entries += [(("observation/exterior_image_2_left",), f"camera:{scene[1]}")]
        if wrist:
            entries += [(("observation/wrist_image_left",), f"camera:{wrist}")]
        entries += [
            (("observation/joint_position",), "state[0:7]"),
            (("observation/gripper_position",), "state[7:8]"),
        ]
    elif obs_format == "libero":
        entries += [(("observation/image",), f"camera:{scene[0]}")]
        if wrist:
            entries += [(("observation/wrist_image",), f"camera:{wrist}")]
        entries += [(("observation/state",), "state")]
    else:
        entries += [
            (("images", name), f"camera_chw:{cam}") for name, cam in zip(("cam_high", "cam_low"), scene)
        ]
        if wrist:
            entries += [(("images", "cam_left_wrist"), f"camera_chw:{wrist}")]
        entries += [(("state",), "state")]
    entries += [(("prompt",), "instruction")]
    if depth:
        entries += [((f"roboview/depth/{cam}",), f"depth:{cam}") for cam in cameras]
    return WireFormat(obs_format, tuple(entries))


def episode_message(episode: Episode) -> dict:
    """What RoboView's own server needs to reset a stateful policy (sent only to a server that asks)."""
    return {
        "task": episode.task,
        "seed": episode.seed,
        "image_size": episode.image_size,
        "cameras": {
            name: {"pos": list(p.pos), "quat": list(p.quat), "fovy": p.fovy}
            for name, p in episode.cameras.items()
        },
    }


def episode_from_message(message: dict, instruction: str) -> Episode:
    from roboview.sim.cameras import CameraPose

    cameras = {
        name: CameraPose(name, tuple(c["pos"]), tuple(c["quat"]), float(c["fovy"]))
        for name, c in message.get("cameras", {}).items()
    }
    return Episode(
        str(message["task"]), instruction, int(message["seed"]), cameras, int(message["image_size"])
    )


# ---------------------------------------------------------------------------------------------------------------
