"""What the command line reads off a config dataclass: a field's kind (a registry-typed field, a nested config), its
default, and its description (the comment above it) and a class's own (its docstring's first paragraph)."""

from __future__ import annotations

import dataclasses
import re
import types
import typing

import draccus
from draccus.wrappers import docstring

_PRAGMA = re.compile(r"^(type:|noqa|pragma|fmt:)")


def is_choice(kind: object) -> bool:
    """Whether a field holds a registry type (`--X.type=NAME` picks the class)."""
    return isinstance(kind, type) and issubclass(kind, draccus.ChoiceRegistry)


def dataclass_of(kind: object) -> type | None:
    """The dataclass a field holds (also `X | None`), None for a plain value."""
    if isinstance(kind, type) and dataclasses.is_dataclass(kind):
        return kind
    if typing.get_origin(kind) in (typing.Union, types.UnionType):
        found = [a for a in typing.get_args(kind) if isinstance(a, type) and dataclasses.is_dataclass(a)]
        return found[0] if len(found) == 1 else None
    return None


def field_default(f: dataclasses.Field) -> object:
    """A field's default (its factory's value), `dataclasses.MISSING` for a required field or a factory that
    refuses."""
    if f.default is not dataclasses.MISSING:
        return f.default
    if f.default_factory is not dataclasses.MISSING:
        try:
            return f.default_factory()
        except Exception:  # a factory that refuses (e.g. "--policy.type is required"): no default
            return dataclasses.MISSING
    return dataclasses.MISSING


def field_help(cls: type, name: str) -> str:
    """Field `name`'s description: the comment above it (else a docstring below it, else an inline comment), then
    what `cls.help_details[name]()` adds."""
    # The class that declares the field (a mixin's field, e.g. a served policy's connection block, is commented
    # in the mixin's source).
    owner = next((k for k in cls.__mro__ if name in getattr(k, "__annotations__", {})), cls)
    try:
        doc = docstring.get_attribute_docstring(owner, name)
    except (RuntimeWarning, OSError, TypeError):
        doc = docstring.AttributeDocString()
    inline = "" if _PRAGMA.match(doc.comment_inline) else doc.comment_inline
    text = " ".join((doc.comment_above or doc.docstring_below or inline).split())
    details = getattr(cls, "help_details", {}).get(name)
    return f"{text} {details()}".strip() if details is not None else text


def class_help(cls: type) -> str:
    """The first paragraph of a class's docstring (not dataclasses' generated signature)."""
    doc = cls.__doc__ or ""
    if doc.startswith(f"{cls.__name__}("):
        return ""
    return " ".join(doc.strip().split("\n\n")[0].split())
