"""`--help`: one layout for every command, read off its config dataclasses (each field's comment is its flag's
description)."""

from __future__ import annotations

import dataclasses
import enum
import os
import shutil
import sys
import textwrap
import types
import typing
from collections.abc import Sequence
from dataclasses import dataclass

from roboview.core.cli_fields import class_help, dataclass_of, field_default, field_help, is_choice

# Every flag is a config dataclass field; its description is the comment on the lines directly above the field
# (a field without its own comment has none). A config class may also define, as plain class attributes:
#   help_groups = {"title": ("field", …)}  fields listed after the common ones, under that title (advanced settings);
#   help_details = {"field": callable}     text computed when --help runs, appended to the field's description
#                                          (from a registry, so it cannot go stale).


@dataclass(frozen=True)
class Flag:
    """One --flag as --help shows it."""

    name: str
    metavar: str
    help: str
    default: str | None  # as shown; None: required


@dataclass
class Section:
    """A heading of --help and its flags."""

    title: str  # "" for the command's own flags
    description: str = ""
    flags: list[Flag] = dataclasses.field(default_factory=list)
    shown_empty: bool = False  # listed even without flags (a registered type with no settings of its own)


def _shown(value: object) -> str | None:
    """A default as it is typed on the command line (lists comma-separated, booleans true/false)."""
    if value is dataclasses.MISSING:
        return None
    if value is None:
        return "none"
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, enum.Enum):
        return str(value.value)
    if isinstance(value, (list, tuple, set, frozenset)):
        return ",".join(map(str, value)) or "empty"
    if isinstance(value, str):
        return value or "empty"
    return str(value)


def _metavar(kind: object) -> str:
    origin, args = typing.get_origin(kind), typing.get_args(kind)
    if origin in (typing.Union, types.UnionType):
        rest = [a for a in args if a is not type(None)]
        return _metavar(rest[0]) if len(rest) == 1 else "|".join(map(_metavar, rest))
    if origin is typing.Literal:
        return "{" + ",".join(map(str, args)) + "}"
    if origin in (list, tuple, set, frozenset) or kind in (list, tuple):
        return "a,b,…"
    if isinstance(kind, type) and issubclass(kind, enum.Enum):
        return "{" + ",".join(str(m.value) for m in kind) + "}"
    return getattr(kind, "__name__", str(kind))


@dataclass
class _Layout:
    main: list[Section] = dataclasses.field(default_factory=list)
    groups: list[Section] = dataclasses.field(default_factory=list)
    choices: list[Section] = dataclasses.field(default_factory=list)
    # registry path → the type given with --help
    chosen: dict[str, str] = dataclasses.field(default_factory=dict)


def _walk(
    cls: type, prefix: str, section: Section, layout: _Layout, skip: frozenset[str] = frozenset()
) -> None:
    """Add `cls`'s fields (flags `--{prefix}field`) to `section`, nested configs as sections of their own."""
    hints = typing.get_type_hints(cls)
    grouped = {name: title for title, names in getattr(cls, "help_groups", {}).items() for name in names}
    groups: dict[str, Section] = {}
    for f in dataclasses.fields(cls):
        if not f.init or f.name in skip:
            continue
        kind, flag = hints.get(f.name, f.type), f"--{prefix}{f.name}"
        target = section
        if f.name in grouped:
            title = grouped[f.name]
            if title not in groups:
                groups[title] = Section(title)
                layout.groups.append(groups[title])
            target = groups[title]
        if is_choice(kind):
            _walk_choice(kind, f, cls, f"{prefix}{f.name}", target, layout)
        elif (nested := dataclass_of(kind)) is not None:
            sub = Section(f"--{prefix}{f.name}.*", field_help(cls, f.name) or class_help(nested))
            (layout.groups if f.name in grouped else layout.main).append(sub)
            _walk(nested, f"{prefix}{f.name}.", sub, layout)
        else:
            target.flags.append(Flag(flag, _metavar(kind), field_help(cls, f.name), _shown(field_default(f))))


def _walk_choice(
    kind: type, f: dataclasses.Field, owner: type, path: str, section: Section, layout: _Layout
) -> None:
    """A registry-typed field (`--policy.type=NAME`): the type flag and the fields every type shares in `section`;
    each type's own fields under a heading of their own (a type extending another lists only what it adds)."""
    known = dict(kind.get_known_choices())
    default = field_default(f)
    shown = kind.get_choice_name(type(default)) if type(default) in known.values() else None
    what = field_help(owner, f.name) or class_help(kind)
    section.flags.append(
        Flag(
            f"--{path}.type",
            "{" + ",".join(known) + "}",
            f"{what} Each type's own flags follow under --{path}.type=NAME (with "
            f"--{path}.type=NAME, --help lists that type's only).".strip(),
            shown,
        )
    )
    shared = (
        frozenset(x.name for x in dataclasses.fields(kind)) if dataclasses.is_dataclass(kind) else frozenset()
    )
    if shared:
        _walk(kind, f"{path}.", section, layout)
    listed: list[type] = []
    for name, choice in known.items():
        about, seen = getattr(choice, "doc", "") or class_help(choice), shared
        # Fields a type has in common with a type listed before it (a shared base config) are listed there only.
        for ancestor in choice.__mro__[1:]:
            if ancestor is kind or not (dataclasses.is_dataclass(ancestor) and issubclass(ancestor, kind)):
                continue
            earlier = next((c for c in listed if issubclass(c, ancestor)), None)
            if earlier is not None:
                seen = frozenset(x.name for x in dataclasses.fields(ancestor))
                common = [x.name for x in dataclasses.fields(ancestor) if x.init and x.name not in shared]
                if common:
                    about += (
                        f". Shares the flags of --{path}.type={kind.get_choice_name(earlier)}: "
                        f"{', '.join(common)}."
                    )
                break
        listed.append(choice)
        if layout.chosen.get(path, name) != name:
            continue
        sub = Section(f"--{path}.type={name}", about.strip(), shown_empty=True)
        layout.choices.append(sub)
        _walk(choice, f"{path}.", sub, layout, skip=seen)


def help_sections(config_class: type, args: Sequence[str] = ()) -> list[Section]:
    """--help's sections in order: the command's own flags, each nested config's common flags, the advanced groups
    (`help_groups`), then each registered type's own flags (only the type named in `args`, if one is)."""
    chosen = dict(arg[2:].split(".type=", 1) for arg in args if arg.startswith("--") and ".type=" in arg)
    layout = _Layout(chosen=chosen)
    top = Section("")
    top.flags += [
        Flag("-h, --help", "", "Show this help and exit.", ""),
        Flag(
            "--config_path",
            "str",
            "A YAML file of these settings, nested as the flags are (--a.b=1 "
            "is `a: {b: 1}`); flags on the command line override it.",
            "none",
        ),
    ]
    layout.main.append(top)
    _walk(config_class, "", top, layout)
    return [s for s in layout.main + layout.groups + layout.choices if s.flags or s.shown_empty]


def _prog(config_class: type) -> str:
    script = os.path.basename(sys.argv[0]) if sys.argv else ""
    if script.startswith("roboview-"):
        return script
    module = config_class.__module__
    if module == "__main__":
        spec = getattr(sys.modules["__main__"], "__spec__", None)
        module = spec.name if spec is not None else script
    return f"python -m {module}"


def _summary_line(config_class: type) -> str:
    """The command's first docstring paragraph (its module's), for the top of --help."""
    doc = getattr(sys.modules.get(config_class.__module__), "__doc__", None) or ""
    return " ".join(doc.strip().split("\n\n")[0].split())


def format_help(config_class: type, args: Sequence[str] = ()) -> str:
    """The text of `--help`: usage, what the command does, then every flag with its description and default."""
    width = max(60, min(shutil.get_terminal_size().columns - 2, 120))
    sections = help_sections(config_class, args)
    required = [
        f"{f.name}={'NAME' if f.name.endswith('.type') else 'VALUE'}"
        for s in sections
        for f in s.flags
        if f.default is None
    ]
    out = [" ".join(["usage:", _prog(config_class), *required, "[--FLAG=VALUE ...]"]), ""]
    if summary := _summary_line(config_class):
        out += [*textwrap.wrap(summary, width, break_on_hyphens=False), ""]
    for section in sections:
        if section.title:
            # (continuation lines indented 4: a line indented 2 starts a flag)
            out += textwrap.wrap(
                f"{section.title}: {section.description}".strip(),
                width,
                subsequent_indent="    ",
                break_on_hyphens=False,
                break_long_words=False,
            )
        for flag in section.flags:
            head = f"  {flag.name} {flag.metavar}".rstrip()
            default = (
                "(required)" if flag.default is None else f"(default: {flag.default})" if flag.default else ""
            )
            body = textwrap.wrap(
                f"{flag.help} {default}".strip(), width - 24, break_on_hyphens=False, break_long_words=False
            ) or [""]
            if len(head) <= 22:
                out.append(f"{head:<24}{body[0]}")
                body = body[1:]
            else:
                out.append(head)
            out += [" " * 24 + line for line in body]
        out.append("")
    return "\n".join(out).rstrip() + "\n"
