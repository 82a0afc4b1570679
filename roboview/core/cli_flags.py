"""The command line as RoboView writes it, rewritten into what draccus reads: renamed flags spelled as their new
names (one warning each) and comma-separated lists bracketed."""

from __future__ import annotations

import dataclasses
import sys
import typing
from collections.abc import Sequence

import draccus

from roboview.core.cli_fields import dataclass_of, is_choice

# --- renamed flags -------------------------------------------------------------------------------------
#
# A config class that moved settings (e.g. into a nested config) keeps the old flags working with
#   flag_aliases = {"old_field": "new.path"}   (a class attribute) --{prefix}old_field=V is read as
#                                              --{prefix}new.path=V, with one warning line naming it.
# For a registry-typed field (`--policy.type=NAME`), the aliases of the type named on the command line apply.


def flag_aliases(config_class: type, args: Sequence[str], prefix: str = "") -> dict[str, str]:
    """Every `--old` flag of `config_class` (nested configs and the chosen registry types included) →
    `--new`."""
    own = getattr(config_class, "flag_aliases", {})
    found = {f"--{prefix}{old}": f"--{prefix}{new}" for old, new in own.items()}
    hints = typing.get_type_hints(config_class)
    for f in dataclasses.fields(config_class):
        kind = hints.get(f.name)
        if is_choice(kind):
            given = [a.split("=", 1)[1] for a in args if a.startswith(f"--{prefix}{f.name}.type=")]
            choice = dict(kind.get_known_choices()).get(given[-1]) if given else None
            if choice is not None:
                found |= flag_aliases(choice, args, f"{prefix}{f.name}.")
        elif (nested := dataclass_of(kind)) is not None:
            found |= flag_aliases(nested, args, f"{prefix}{f.name}.")
    return found


def renamed_flags(config_class: type, args: list[str]) -> list[str]:
    """`args` with every old flag spelled as its new one; one `warning:` line on stderr per old flag used."""
    aliases = flag_aliases(config_class, args)
    if not aliases:
        return args
    out, warned = [], set()
    for arg in args:
        flag, sep, value = arg.partition("=")
        if flag in aliases:
            if flag not in warned:
                print(f"warning: {flag} is deprecated; use {aliases[flag]}", file=sys.stderr)
                warned.add(flag)
            arg = aliases[flag] + sep + value
        out.append(arg)
    return out


# --- lists ---------------------------------------------------------------------------------------------


def _list_flags(config_class: type, prefix: str = "") -> set[str]:
    """The --flags of `config_class` (nested configs included) whose field holds a list or tuple."""
    found: set[str] = set()
    hints = typing.get_type_hints(config_class)
    for f in dataclasses.fields(config_class):
        kind = hints.get(f.name)
        if (
            isinstance(kind, type)
            and dataclasses.is_dataclass(kind)
            and not issubclass(kind, draccus.ChoiceRegistry)
        ):
            found |= _list_flags(kind, f"{prefix}{f.name}.")
            continue
        outer = [typing.get_origin(k) for k in (kind, *typing.get_args(kind))]
        if list in outer or tuple in outer:
            found.add(f"--{prefix}{f.name}")
    return found


def comma_lists(config_class: type, args: list[str]) -> list[str]:
    """Every list flag is written `a,b` on RoboView's command lines, as every string list is; draccus reads
    lists as `[a,b]`, so `--x=a,b` becomes `--x=[a,b]` (a bracketed value passes unchanged)."""
    flags = _list_flags(config_class)
    out = []
    for arg in args:
        flag, sep, value = arg.partition("=")
        if sep and flag in flags and not value.startswith("["):
            arg = f"{flag}=[{value}]"
        out.append(arg)
    return out
