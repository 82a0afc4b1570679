"""The policy types: the modules that define them, loaded by name, and a config by type name.

Each module listed here (or named by a `roboview.policies` entry point of another package) defines and
registers a `PolicyConfig` subclass of `roboview.policies.base`; they import `roboview.policies.base`, so the list lives
here, above them, and they are imported on demand, never when `roboview.policies.base` is.
"""

from __future__ import annotations

import importlib
import importlib.metadata
from typing import Any

from roboview.policies.base import PolicyConfig, registered_types

# Builtin policy types: modules that define and register a PolicyConfig subclass.
BUILTIN_MODULES = (
    "roboview.policies.adapters",
    "roboview.policies.vision",
    "roboview.policies.lerobot_policy",
    "roboview.policies.vlm.simple",
    "roboview.policies.vlm.moka",
    "roboview.policies.openpi",
    "roboview.policies.lerobot_async",
    "roboview.policies.vla_eval",
)
# Third-party packages add types through entry points in this group, each naming such a module.
ENTRY_POINT_GROUP = "roboview.policies"


def load_policy_types() -> tuple[str, ...]:
    """Import the builtin policy modules and every `roboview.policies` entry point; the type names."""
    for module in BUILTIN_MODULES:
        importlib.import_module(module)
    for entry in importlib.metadata.entry_points(group=ENTRY_POINT_GROUP):
        importlib.import_module(entry.value.split(":")[0])
    return registered_types()


def policy_config(type_name: str, **settings: Any) -> PolicyConfig:
    """The config of policy type `type_name` with `settings` (what `--policy.type=… --policy.x=…`
    gives)."""
    known = load_policy_types()
    if type_name not in known:
        raise ValueError(f"unknown policy type {type_name!r}; allowed: {', '.join(known)}")
    return PolicyConfig.get_choice_class(type_name)(**settings)


def policy_class(type_name: str) -> type[PolicyConfig] | None:
    """The config class of policy type `type_name`; None for a name no registered type has (a run converted from
    another harness records its own name there)."""
    return PolicyConfig.get_choice_class(type_name) if type_name in load_policy_types() else None


def row_name_pattern(type_name: str, options: dict[str, Any]) -> str:
    """The fnmatch pattern the rows' `policy` column of a run of `type_name` with `options` (run.json's
    policy_options) matches when --policy.name was not given: the type's `row_name`, "+sgl" after it when the SGL
    wrapped the policy; `type_name` itself for a converted run."""
    cls = policy_class(type_name)
    if cls is None:
        return type_name
    try:
        pattern = cls.row_name.format_map({**options, "type": type_name})
    except (KeyError, IndexError, ValueError):  # options that do not name what the pattern reads
        pattern = cls.row_name.split("{")[0] + "*"
    return pattern + ("+sgl" if options.get("sgl") else "")


def recorded_config(run: dict[str, Any]) -> PolicyConfig:
    """The policy config a results folder's run.json records (type, options, checkpoint, name and control), rebuilt
    as a replay needs it; ValueError for a type no registered one has (a run converted from another harness)."""
    import dataclasses

    cls = policy_class(str(run.get("policy") or ""))
    if cls is None:
        raise ValueError(
            f"run.json's policy {run.get('policy')!r} is no policy type here (a run converted from another harness "
            "cannot be re-run)"
        )
    settings = dict(run.get("policy_options") or {})
    if run.get("policy_path"):
        settings["path"] = run["policy_path"]
    if run.get("policy_name"):
        settings["name"] = run["policy_name"]
    if "control" in {f.name for f in dataclasses.fields(cls)}:
        settings["control"] = run.get("control", "joint")
    return cls.from_options(settings)
