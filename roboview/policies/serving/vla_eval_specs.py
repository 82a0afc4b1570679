"""What a vla-eval model server declares in its HELLO answer, mapped onto RoboView's env: the negotiation.

A vla-eval server (`vla_eval.model_servers`) declares `action_spec` and `observation_spec`, each a
`{component: DimSpec dict}` (`vla_eval.specs`), and `observation_params` (`send_state`,
`send_wrist_image`, …). `negotiate` turns them into what the client sends each step and how each
answered action becomes the env's action, or raises `SpecMismatch` naming the field, what the server
declared and what RoboView provides: before any episode runs.

| server declares                                              | RoboView                                 |
|--------------------------------------------------------------|------------------------------------------|
| action `raw` (one component)                                 | `--policy.control` (default joint), as is |
| action `joint_positions` (7) + gripper, or 8                 | joint                                    |
| `position` delta_xyz + `rotation` axis_angle + gripper       | ee_delta                                 |
| `position` absolute_xyz + `rotation` axis_angle + gripper    | ee_abs                                   |
| gripper binary_close_positive / _negative / continuous_01 / binary_close_01 | the env's gripper (joint: 0 open … 1 closed; EE: -1 open, +1 close) |
| observation `state` joint_positions                          | `observation.state` (7 joints + gripper) |
| observation `state` raw                                      | `observation.state`; `observation.ee_state` under an EE control |
| observation `state` eef_pos3_axisangle3_gripper2             | `observation.ee_state`                   |
| observation `image` (rgb_hwc_uint8)                          | every camera of `--policy.cameras`, by name |
| observation `<camera>` (rgb_hwc_uint8)                       | that camera (or `--policy.camera_map`)   |
| observation `language`                                       | the instruction (`task_description`)     |

On LIBERO's scenes the `eef_pos3_axisangle3_gripper2` state is built as vla-eval's LIBERO benchmark builds it (float64;
the quaternion's axis-angle by `vla_eval.rotation.quat_to_axisangle`, or robosuite's formula where the server's
`observation_params` ask for `quat_no_antipodal`, as OpenVLA-OFT's does), so such a server reads what it reads there.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from vla_eval.specs import (
    GRIPPER_01,
    GRIPPER_CLOSE_POS,
    POSITION_ABSOLUTE,
    POSITION_DELTA,
    ROTATION_AA,
    STATE_EEF_POS_AA_GRIP,
    STATE_JOINT,
    DimSpec,
)

from roboview.tasks import camera_names
from roboview.tasks.env import EE_STATE_KEY, STATE_KEY
from roboview.tasks.world import proprio_of

JOINT_TARGETS = DimSpec(
    "joints", 7, "joint_positions", description="absolute Panda joint position targets (rad)"
)
# RoboView's action layout of each control (the env's action_space) and its state, in vla-eval's vocabulary: what
# the benchmark side declares (roboview.integrations.vla_eval) and what the client maps a server's specs onto.
ACTION_SPECS: dict[str, dict[str, DimSpec]] = {
    "joint": {"joints": JOINT_TARGETS, "gripper": GRIPPER_01},
    "ee_delta": {"position": POSITION_DELTA, "rotation": ROTATION_AA, "gripper": GRIPPER_CLOSE_POS},
    "ee_abs": {"position": POSITION_ABSOLUTE, "rotation": ROTATION_AA, "gripper": GRIPPER_CLOSE_POS},
    # Meta-World's: hand position delta + gripper effort (+1 closes).
    "xyz_delta": {"position": POSITION_DELTA, "gripper": GRIPPER_CLOSE_POS},
}
STATE_SPECS: dict[str, DimSpec] = {
    "joint": STATE_JOINT,
    "ee_delta": STATE_EEF_POS_AA_GRIP,
    "ee_abs": STATE_EEF_POS_AA_GRIP,
    "xyz_delta": DimSpec(
        "state", 4, "raw", description="Meta-World's agent_pos: hand position, gripper opening"
    ),
}
# Action width of each control: 7 joint targets + closure; 3 position + 3 axis-angle + gripper; 3 position + gripper.
ACTION_DIMS = {control: sum(spec.dims for spec in specs.values()) for control, specs in ACTION_SPECS.items()}

GRIPPERS = ("binary_close_positive", "binary_close_negative", "continuous_01", "binary_close_01", "raw")
POSITIONS = {"delta_xyz": "ee_delta", "absolute_xyz": "ee_abs"}
JOINT_FORMATS = ("joint_positions", "raw")
IMAGE_FORMAT = "rgb_hwc_uint8"
STATES = {
    "joint_positions": "observation.state (7 joint positions + gripper closure)",
    "raw": "observation.state, or observation.ee_state under an EE control",
    "eef_pos3_axisangle3_gripper2": "observation.ee_state (position, axis-angle, 2 finger positions)",
}


class SpecMismatch(ValueError):
    """The server declares something RoboView cannot give or take; names the field, both sides."""


def _mismatch(field: str, declared: str, provides: str, fix: str = "") -> SpecMismatch:
    return SpecMismatch(
        f"vla-eval server's {field}: it declares {declared}; RoboView provides {provides}"
        + (f" ({fix})" if fix else "")
    )


@dataclass(frozen=True)
class Negotiated:
    """What was agreed: the env control, the cameras sent (wire name → RoboView camera), the state sent
    (an observation key or None), and how an answered action maps onto the env's."""

    control: str
    cameras: tuple[tuple[str, str], ...]
    state_key: str | None
    # The server's action components in wire order: (name, dims, format).
    action: tuple[tuple[str, int, str], ...]
    gripper: str
    # LIBERO's state axis-angle without vla-eval's antipodal normalization (observation_params quat_no_antipodal).
    quat_no_antipodal: bool = False

    @property
    def observed_cameras(self) -> tuple[str, ...]:
        return tuple(dict.fromkeys(cam for _, cam in self.cameras))

    @property
    def action_dims(self) -> int:
        return ACTION_DIMS[self.control]

    def state(self, observation) -> np.ndarray:
        """The state sent: on LIBERO's scenes an EE state as vla-eval's LIBERO benchmark builds it, else the
        env's, float32."""
        proprio = proprio_of(observation) if self.state_key == EE_STATE_KEY else None
        if proprio is None:
            return np.asarray(observation[self.state_key], np.float32)
        return libero_state(proprio, self.quat_no_antipodal)

    def env_action(self, action: np.ndarray) -> np.ndarray:
        """The env action for one answered action; ValueError (the episode's failure) for a wrong width."""
        a = np.array(action, np.float32).reshape(-1)
        if a.shape[0] != self.action_dims or not np.isfinite(a).all():
            fits = [c for c, d in ACTION_DIMS.items() if d == a.shape[0] and c != self.control]
            hint = (
                f": pass --policy.control={' or --policy.control='.join(fits)} (the spec is raw: the checkpoint decides)"
                if self.gripper == "raw" and fits
                else ""
            )
            raise ValueError(
                f"the vla-eval server answered an action of {a.shape[0]} values {a[:8].tolist()}; its "
                f"spec {[(n, f) for n, _, f in self.action]} under {self.control} control takes "
                f"{self.action_dims} finite values{hint}"
            )
        if self.gripper == "raw":  # the env's own convention: passed as sent
            return a
        closure = gripper_closure(float(a[-1]), self.gripper)
        a[-1] = closure if self.control == "joint" else 2.0 * closure - 1.0
        return a


def libero_state(proprio: np.ndarray, no_antipodal: bool) -> np.ndarray:
    """vla-eval's LIBERO benchmark's `_proprio_state` from (eef pos, eef quat xyzw, gripper qpos): float64 (8,)."""
    from vla_eval.rotation import quat_to_axisangle

    pos, quat, grip = proprio[:3], proprio[3:7], proprio[7:]
    return np.concatenate(
        [pos, _axisangle_robosuite(quat) if no_antipodal else quat_to_axisangle(quat), grip]
    )


def _axisangle_robosuite(quat: np.ndarray) -> np.ndarray:
    """robosuite's quat2axisangle (no antipodal normalization), float32: what vla-eval's LIBERO benchmark uses under
    `quat_no_antipodal` (`vla_eval.benchmarks.libero.benchmark`, whose import sets EGL rendering)."""
    q = quat.copy()
    q[3] = min(max(q[3], -1.0), 1.0)
    den = np.sqrt(1.0 - q[3] * q[3])
    if math.isclose(den, 0.0):
        return np.zeros(3, dtype=np.float32)
    return (q[:3] * 2.0 * math.acos(q[3]) / den).astype(np.float32)


def gripper_closure(value: float, fmt: str) -> float:
    """The closure in [0, 1] (1 closed) a gripper command of convention `fmt` means (binary ones as
    LIBERO's benchmark discretizes them: the sign, or above one half)."""
    if fmt == "binary_close_positive":
        return 1.0 if value >= 0 else 0.0
    if fmt == "binary_close_negative":
        return 1.0 if value <= 0 else 0.0
    if fmt == "binary_close_01":
        return 1.0 if value > 0.5 else 0.0
    return float(np.clip(value, 0.0, 1.0))  # continuous_01


def parse_specs(payload: dict, key: str) -> dict[str, DimSpec]:
    """`{component: DimSpec}` of a HELLO payload's `action_spec` / `observation_spec` (wire order kept)."""
    return {name: DimSpec.from_dict(d) for name, d in (payload.get(key) or {}).items()}


def negotiate(
    hello: dict, cameras: tuple[str, ...], camera_map: dict[str, str], control: str = ""
) -> Negotiated:
    """The agreement for a server's HELLO answer; `cameras` serve a generic `image` spec, `camera_map`
    renames the server's camera keys, `control` ("" = from the spec) decides a `raw` action spec."""
    chosen, action, gripper = _action(parse_specs(hello, "action_spec"), control)
    params = hello.get("observation_params") or {}
    sent, state_key = _observation(
        parse_specs(hello, "observation_spec"), params, cameras, camera_map, chosen
    )
    return Negotiated(chosen, sent, state_key, action, gripper, bool(params.get("quat_no_antipodal")))


def _action(spec: dict[str, DimSpec], control: str) -> tuple[str, tuple, str]:
    layout = tuple((name, s.dims, s.format) for name, s in spec.items())
    formats = [s.format for s in spec.values()]
    if not spec or formats == ["raw"]:  # checkpoint-specific (LeRobot's server): the flag decides
        chosen = control or "joint"
        return chosen, layout, "raw"
    grip = [s for name, s in spec.items() if name == "gripper"]
    if len(grip) != 1:
        raise _mismatch(
            "action_spec",
            f"components {list(spec)} without one 'gripper'",
            "joint, ee_delta and ee_abs controls, each with a gripper command",
        )
    if grip[0].format not in GRIPPERS:
        raise _mismatch(
            "action_spec['gripper']",
            f"format {grip[0].format!r}",
            f"the gripper conventions {', '.join(GRIPPERS)}",
        )
    arm = {name: s for name, s in spec.items() if name != "gripper"}
    if len(arm) == 1 and next(iter(arm.values())).format in JOINT_FORMATS:
        ((name, s),) = arm.items()
        if s.dims not in (0, 7):
            raise _mismatch(f"action_spec[{name!r}]", f"{s.dims} joint positions", "7 Panda joint targets")
        chosen = "joint"
    else:
        position, rotation = arm.get("position"), arm.get("rotation")
        extra = sorted(set(arm) - {"position", "rotation"})
        if extra:
            name = extra[0]
            raise _mismatch(
                f"action_spec[{name!r}]",
                f"format {arm[name].format!r}",
                "no control for it (joint positions, or position + rotation + gripper)",
            )
        if position is None or position.format not in POSITIONS:
            raise _mismatch(
                "action_spec['position']",
                f"format {position.format!r}" if position else "no position",
                "delta_xyz (ee_delta control) and absolute_xyz (ee_abs control)",
            )
        if rotation is None or rotation.format != "axis_angle" or rotation.dims != 3:
            raise _mismatch(
                "action_spec['rotation']",
                f"format {rotation.format!r} ({rotation.dims} dims)" if rotation else "no rotation",
                "axis_angle (3) only: no control takes Euler angles, quaternions or 6-D rotations",
            )
        chosen = POSITIONS[position.format]
    if control and control != chosen:
        raise _mismatch(
            "action_spec",
            f"{[(n, s.format) for n, s in spec.items()]} ({chosen} control)",
            f"--policy.control={control}",
            "leave --policy.control empty to follow the server",
        )
    return chosen, layout, grip[0].format


def _observation(
    spec: dict[str, DimSpec], params: dict, cameras: tuple[str, ...], camera_map: dict[str, str], control: str
) -> tuple[tuple[tuple[str, str], ...], str | None]:
    sent: list[tuple[str, str]] = []
    state_key = None
    if not spec:  # a server that declares nothing: the flags' cameras and the joint state
        sent = [(cam, cam) for cam in cameras]
        state_key = STATE_KEY if control == "joint" else EE_STATE_KEY
    for name, s in spec.items():
        if s.format == IMAGE_FORMAT and name == "image":
            sent += [(cam, cam) for cam in cameras]
        elif s.format == IMAGE_FORMAT:
            cam = camera_map.get(name, name)
            if cam not in camera_names():
                raise _mismatch(
                    f"observation_spec[{name!r}]",
                    f"a camera named {name!r}",
                    f"the cameras {', '.join(camera_names())}",
                    f"map it with --policy.camera_map={name}=CAMERA",
                )
            sent.append((name, cam))
        elif name == "language" or s.format == "language":
            continue  # the instruction goes with every observation
        elif name == "state":
            if s.format not in STATES:
                raise _mismatch(
                    "observation_spec['state']",
                    f"format {s.format!r} ({s.dims} dims)",
                    "; ".join(f"{k}: {v}" for k, v in STATES.items()),
                )
            ee = s.format == "eef_pos3_axisangle3_gripper2" or (s.format == "raw" and control != "joint")
            state_key = EE_STATE_KEY if ee else STATE_KEY
        else:
            raise _mismatch(
                f"observation_spec[{name!r}]",
                f"format {s.format!r}",
                "camera images (rgb_hwc_uint8), language and state",
            )
    if params.get("send_state") and state_key is None:
        state_key = STATE_KEY if control == "joint" else EE_STATE_KEY
    if params.get("send_wrist_image") and "wrist" not in {cam for _, cam in sent}:
        raise _mismatch(
            "observation_params['send_wrist_image']",
            "True (a wrist image)",
            f"the cameras {', '.join(cam for _, cam in sent) or 'none'} here",
            "add wrist to --policy.cameras",
        )
    if not sent:
        raise _mismatch(
            "observation_spec", "no camera image", "camera images", "RoboView's policies see images"
        )
    return tuple(sent), state_key
