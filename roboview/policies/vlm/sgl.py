"""The Semantic Grounding Layer (SGL): ground the instruction in the scene before any policy acts.

It wraps any policy that reads an instruction — the VLM agents and LeRobot checkpoints alike — and,
at the first observation of an episode, runs the paper's three stages:

1. **Scene parsing** — the appendix prompt (`prompts.SGL_SCENE_PARSE`) asks a VLM for every object
   with its name, categories, color, size, position and state.
2. **Ambiguity detection** — the instruction is ambiguous when it names the object to move by a
   generic word ("the small *object*") or when another object shares a category with it.
3. **Attribute selection and refinement** — attributes are tried in the paper's priority
   color > state > size > position; the first one that tells the object apart from every object it
   shares a category with (with none, simply the first: its color) goes in front of its name:
   "put the small object into the yellow box" → "put the small red cube into the yellow box".

The wrapped policy is reset with the refined instruction; the refined instruction and whether the
original was ambiguous are recorded per episode.
"""

from __future__ import annotations

import dataclasses
import re
from dataclasses import dataclass, field
from typing import Any, ClassVar

import numpy as np

from roboview.policies.base import Episode, Policy, PolicyConfig
from roboview.policies.vlm.client import Endpoint, VLMClient, endpoint_aliases
from roboview.policies.vlm.prompts import SGL_SCENE_PARSE
from roboview.tasks.env import IMAGE_KEY

PRIORITY = ("color", "state", "size", "position")
GENERIC_NOUNS = ("object", "thing", "item", "geometry", "solid")
# Values that describe nothing (the prompt's fallbacks).
UNINFORMATIVE = {"normal", "", None}


@dataclass(frozen=True)
class Grounding:
    instruction: str
    refined: str
    ambiguous: bool
    # The attribute chosen to tell the object apart ("" when the instruction was left as it was).
    attribute: str


def check_scene(answer: Any) -> list[dict]:
    """The parsed scene: a non-empty JSON list of objects with the prompt's attributes."""
    if isinstance(answer, dict) and isinstance(answer.get("objects"), list):
        answer = answer["objects"]  # a common wrapping
    if not isinstance(answer, list) or not answer:
        raise ValueError("expected a non-empty JSON list of objects")
    for obj in answer:
        if not isinstance(obj, dict) or "object_type" not in obj or "name" not in obj:
            raise ValueError(f"every object needs at least object_type and name, got {obj!r}")
    return answer


def _categories(obj: dict) -> set[str]:
    cats = obj.get("category") or []
    return {str(c).lower() for c in (cats if isinstance(cats, list) else [cats])} | {
        str(obj.get("name", "")).lower()
    }


def refine(instruction: str, objects: list[dict]) -> Grounding:
    """Stages 2 and 3 (heuristic rules, as in the paper's appendix) on a parsed scene."""
    manipulated = next((o for o in objects if o.get("object_type") == "manipulation object"), None)
    if manipulated is None:
        return Grounding(instruction, instruction, False, "")
    others = [o for o in objects if o is not manipulated]
    sharing = [o for o in others if _categories(o) & _categories(manipulated)]
    noun = re.search(r"\b(" + "|".join(GENERIC_NOUNS) + r")\b", instruction)
    ambiguous = bool(sharing) or noun is not None
    if not ambiguous:
        return Grounding(instruction, instruction, False, "")
    chosen = ""
    for attribute in PRIORITY:
        value = manipulated.get(attribute)
        if value in UNINFORMATIVE:
            continue
        if all(o.get(attribute) != value for o in sharing):
            chosen = attribute
            break
    name = str(manipulated.get("name") or "object")
    said = instruction[: noun.start()].split()[-3:] if noun is not None else []
    phrase = f"{manipulated[chosen]} {name}" if chosen and str(manipulated[chosen]) not in said else name
    if noun is not None:
        refined = instruction[: noun.start()] + phrase + instruction[noun.end() :]
    else:  # named by its own noun but shared a category: put the attribute in front of that noun
        refined = re.sub(rf"\b{re.escape(name)}\b", phrase, instruction, count=1)
    return Grounding(instruction, refined, True, chosen)


class SemanticGroundingLayer:
    """Wraps `inner`: parses the first frame, refines the instruction, then lets `inner` act."""

    def __init__(self, inner: Policy, endpoint: Endpoint, camera: str) -> None:
        self.inner = inner
        self.name = f"{inner.name}+sgl"
        self.camera = camera
        self.client = VLMClient(endpoint)
        self._episode: Episode | None = None
        self._grounding: Grounding | None = None

    @property
    def failure_reason(self) -> str:
        return getattr(self.inner, "failure_reason", "")

    def reset(self, episode: Episode) -> None:
        self._episode = episode
        self._grounding = None

    def select_action(self, observation: dict[str, np.ndarray]) -> np.ndarray:
        if self._grounding is None:
            rgb = observation[IMAGE_KEY.format(self.camera)]
            prompt = SGL_SCENE_PARSE.replace("{instruction}", self._episode.instruction)
            scene = self.client.ask_json(prompt, [rgb], check_scene)
            grounding = refine(self._episode.instruction, scene)
            self.inner.reset(dataclasses.replace(self._episode, instruction=grounding.refined))
            self._grounding = grounding
        return self.inner.select_action(observation)

    def episode_record(self) -> dict:
        inner = getattr(self.inner, "episode_record", None)
        record = dict(inner()) if inner is not None else {}
        for key, value in self.client.take_stats().items():
            record[key] = record.get(key, 0) + value
        g = self._grounding
        return record | {
            "sgl_instruction": g.refined if g else None,
            "sgl_ambiguous": g.ambiguous if g else None,
            "sgl_attribute": g.attribute if g else None,
        }

    def close(self) -> None:
        self.inner.close()


@dataclass
class SGLConfig:
    """`--sgl.*`: wrap whatever `--policy` builds in the Semantic Grounding Layer."""

    # Wrap the policy in the SGL: a VLM parses the first frame and the instruction is refined ("the small
    # object" → "the small red cube") before the policy acts.
    enable: bool = False
    # The SGL's VLM endpoint; with --sgl.endpoint.model empty, a VLM agent's own endpoint.
    endpoint: Endpoint = field(default_factory=Endpoint)

    # The endpoint's settings the SGL once took as flags of their own (--sgl.model → --sgl.endpoint.model).
    flag_aliases: ClassVar[dict[str, str]] = endpoint_aliases("base_url", "model", "api_key_env")

    @property
    def own_endpoint(self) -> bool:
        """Whether the SGL asks the wrapped VLM agent's endpoint (no model named for the SGL itself)."""
        return not self.endpoint.model

    def endpoint_for(self, policy: PolicyConfig) -> Endpoint:
        own = getattr(policy, "endpoint", None)
        return own if self.own_endpoint and isinstance(own, Endpoint) else self.endpoint

    def wrap(self, policy: PolicyConfig) -> PolicyConfig:
        """`policy` itself when the SGL is off, else a config whose policies are wrapped in it (the endpoint is
        validated now, before any rollout)."""
        if not self.enable:
            return policy
        if self.own_endpoint and self.endpoint.base_url != Endpoint.base_url:
            raise ValueError(
                f"--sgl.endpoint.base_url={self.endpoint.base_url!r} without "
                "--sgl.endpoint.model: name the model on it, or drop the URL to ask the VLM "
                "agent's own endpoint"
            )
        endpoint = self.endpoint_for(policy)
        endpoint.validate("--policy.endpoint." if endpoint is not self.endpoint else "--sgl.endpoint.")
        return GroundedConfig(policy, self)


class GroundedConfig:
    """A policy config wrapped in the SGL: everything is the inner config's, except that its policies are
    grounded, it never batches (the SGL grounds each env's episode), and its options record the SGL."""

    def __init__(self, inner: PolicyConfig, sgl: SGLConfig) -> None:
        self.inner, self.sgl = inner, sgl

    def __getattr__(self, name: str) -> Any:
        if name in ("inner", "sgl") or name.startswith("__"):  # not yet set (unpickling) or a protocol lookup
            raise AttributeError(name)
        return getattr(self.inner, name)

    def __getstate__(self) -> dict:  # picklable for spawned workers despite __getattr__
        return {"inner": self.inner, "sgl": self.sgl}

    def __setstate__(self, state: dict) -> None:
        self.inner, self.sgl = state["inner"], state["sgl"]

    def batchable(self) -> bool:
        return False

    def build_batched(self, view, slots: int) -> None:
        return None

    def options(self) -> dict[str, Any]:
        # As run.json has always recorded them: empty URL and model when the SGL asks the agent's own
        # endpoint.
        e = self.sgl.endpoint
        url = "" if self.sgl.own_endpoint else e.base_url
        return {
            **self.inner.options(),
            "sgl": True,
            "sgl_base_url": url,
            "sgl_model": e.model,
            "sgl_api_key_env": e.api_key_env,
        }

    def build(self, view) -> Policy:
        return SemanticGroundingLayer(
            self.inner.build(view), self.sgl.endpoint_for(self.inner), self.inner.observed_cameras()[0]
        )
