"""Command-line plumbing every RoboView command shares (the verbs, the throughput studies, the integrations' tools):
draccus parsing with readable errors, quiet third-party logs, one `--help` layout for every command, and
Ctrl-C that ends with one line saying what was kept. `roboview.pipelines._cli` adds the flag groups the pipelines
share."""

from __future__ import annotations

import dataclasses
import difflib
import enum
import logging
import os
import re
import shutil
import sys
import textwrap
import types
import typing
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import draccus
from draccus.argparsing import ArgumentParser
from draccus.wrappers import docstring

# MuJoCo picks its GL backend when first imported, which the pipelines do before main() runs:
# the headless defaults must be in place as soon as this module is (it is imported first).
os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")


def _root_cause(exc: BaseException) -> BaseException:
    while exc.__cause__ is not None:
        exc = exc.__cause__
    return exc


def fail(message: str, code: int = 2) -> None:
    """Print `error: message` and exit: no traceback for input a user can fix."""
    print(f"error: {message}", file=sys.stderr)
    raise SystemExit(code)


def _check_choices(config_class: type, args: list[str]) -> None:
    """`--X.type=NAME` for a registry-typed field X must name a registered type (argparse's own
    message for this omits which field and lists choices in a form our errors do not use)."""
    hints = typing.get_type_hints(config_class)
    for f in dataclasses.fields(config_class):
        kind = hints.get(f.name)
        if not (isinstance(kind, type) and issubclass(kind, draccus.ChoiceRegistry)):
            continue
        for arg in args:
            if arg.startswith(f"--{f.name}.type="):
                name = arg.split("=", 1)[1]
                known = sorted(kind.get_known_choices())
                if name not in known:
                    fail(f"unknown {f.name} type {name!r}; allowed: {', '.join(known)}")


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
        if _is_choice(kind):
            given = [a.split("=", 1)[1] for a in args if a.startswith(f"--{prefix}{f.name}.type=")]
            choice = dict(kind.get_known_choices()).get(given[-1]) if given else None
            if choice is not None:
                found |= flag_aliases(choice, args, f"{prefix}{f.name}.")
        elif (nested := _dataclass_of(kind)) is not None:
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


# --- --help: one layout for every command ----------------------------------------------------------------------
#
# Every flag is a config dataclass field; its description is the comment on the lines directly above the field
# (a field without its own comment has none). A config class may also define, as plain class attributes:
#   help_groups = {"title": ("field", …)}  fields listed after the common ones, under that title (advanced settings);
#   help_details = {"field": callable}     text computed when --help runs, appended to the field's description
#                                          (from a registry, so it cannot go stale).

_PRAGMA = re.compile(r"^(type:|noqa|pragma|fmt:)")


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


def _class_help(cls: type) -> str:
    """The first paragraph of a class's docstring (not dataclasses' generated signature)."""
    doc = cls.__doc__ or ""
    if doc.startswith(f"{cls.__name__}("):
        return ""
    return " ".join(doc.strip().split("\n\n")[0].split())


def _default(f: dataclasses.Field) -> object:
    if f.default is not dataclasses.MISSING:
        return f.default
    if f.default_factory is not dataclasses.MISSING:
        try:
            return f.default_factory()
        except Exception:  # a factory that refuses (e.g. "--policy.type is required"): no default
            return dataclasses.MISSING
    return dataclasses.MISSING


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


def _is_choice(kind: object) -> bool:
    return isinstance(kind, type) and issubclass(kind, draccus.ChoiceRegistry)


def _dataclass_of(kind: object) -> type | None:
    """The dataclass a field holds (also `X | None`), None for a plain value."""
    if isinstance(kind, type) and dataclasses.is_dataclass(kind):
        return kind
    if typing.get_origin(kind) in (typing.Union, types.UnionType):
        found = [a for a in typing.get_args(kind) if isinstance(a, type) and dataclasses.is_dataclass(a)]
        return found[0] if len(found) == 1 else None
    return None


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
        if _is_choice(kind):
            _walk_choice(kind, f, cls, f"{prefix}{f.name}", target, layout)
        elif (nested := _dataclass_of(kind)) is not None:
            sub = Section(f"--{prefix}{f.name}.*", field_help(cls, f.name) or _class_help(nested))
            (layout.groups if f.name in grouped else layout.main).append(sub)
            _walk(nested, f"{prefix}{f.name}.", sub, layout)
        else:
            target.flags.append(Flag(flag, _metavar(kind), field_help(cls, f.name), _shown(_default(f))))


def _walk_choice(
    kind: type, f: dataclasses.Field, owner: type, path: str, section: Section, layout: _Layout
) -> None:
    """A registry-typed field (`--policy.type=NAME`): the type flag and the fields every type shares in `section`;
    each type's own fields under a heading of their own (a type extending another lists only what it adds)."""
    known = dict(kind.get_known_choices())
    default = _default(f)
    shown = kind.get_choice_name(type(default)) if type(default) in known.values() else None
    what = field_help(owner, f.name) or _class_help(kind)
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
        about, seen = getattr(choice, "doc", "") or _class_help(choice), shared
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


def _parser(config_class: type) -> ArgumentParser:
    parser = ArgumentParser(config_class=config_class)
    parser.parser.error = fail  # argparse's own errors: one line, not the usage dump before it
    return parser


def _check_flags(parser: ArgumentParser, args: list[str]) -> None:
    """An unknown or misspelled flag: one line naming it, one naming the closest real flags; exit status 2."""
    known = parser.parser._option_string_actions
    unknown = [name for arg in args if arg.startswith("--") and (name := arg.split("=", 1)[0]) not in known]
    if not unknown:
        return
    real = [name for name, action in known.items() if not (action.help or "").startswith("Config file for")]
    close = [match for name in unknown for match in difflib.get_close_matches(name, real, n=1, cutoff=0.6)]
    print(
        f"error: unknown flag{'s' if len(unknown) > 1 else ''} {', '.join(dict.fromkeys(unknown))}",
        file=sys.stderr,
    )
    print(
        f"did you mean {', '.join(dict.fromkeys(close))}? (--help lists every flag)"
        if close
        else "--help lists every flag",
        file=sys.stderr,
    )
    raise SystemExit(2)


def parse[T](config_class: type[T], args: list[str] | None = None) -> T:
    """Parse `args` into `config_class`: `--help` prints `format_help`, an unknown flag names the closest real one,
    validation errors exit with the validator's own message."""
    args = sys.argv[1:] if args is None else list(args)
    if "-h" in args or "--help" in args:
        print(format_help(config_class, args), end="")
        raise SystemExit(0)
    args = renamed_flags(config_class, args)
    parser = _parser(config_class)
    _check_flags(parser, args)
    args = comma_lists(config_class, args)
    _check_choices(config_class, args)
    try:
        return parser.parse_args(args)
    except (draccus.utils.ParsingError, draccus.utils.DecodingError) as exc:
        fail(str(_root_cause(exc)))


# RoboView's own loggers (`__main__`: a pipeline run with `python -m`) log at INFO; every other library's only
# warnings and errors (their INFO lines, such as PyOpenGL's "No OpenGL_accelerate module loaded", say nothing about
# the run).
OWN_LOGGERS = ("__main__", "roboview", "benchmarks")


def setup_environment() -> None:
    """Headless rendering and quiet encoders/progress bars/INFO logs from libraries (ours show progress)."""
    os.environ.setdefault("SVT_LOG", "1")  # SVT-AV1: errors only
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    for name in OWN_LOGGERS:
        logging.getLogger(name).setLevel(logging.INFO)
    for noisy in ("libav", "datasets", "httpx", "urllib3"):  # libraries that set their own loggers' level
        logging.getLogger(noisy).setLevel(logging.WARNING)
    try:
        import datasets

        datasets.disable_progress_bars()
        import av

        av.logging.set_level(av.logging.ERROR)
        _keep_libav_quiet(av)
    except ImportError:
        pass


def _keep_libav_quiet(av) -> None:
    """lerobot's video code calls `av.logging.restore_default_callback()` after every encode, probe and
    concatenation, which puts libav back at its verbose default: each episode then printed lines such as
    "[mp4 @ 0x…] Starting second pass: moving the moov atom …". Restoring keeps our error-only level."""
    restore = av.logging.restore_default_callback
    if getattr(restore, "keeps_level", False):
        return

    def restore_keeping_level() -> None:
        restore()
        av.logging.set_level(av.logging.ERROR)

    restore_keeping_level.keeps_level = True
    av.logging.restore_default_callback = restore_keeping_level


INTERRUPTED = 130  # the exit status of a command ended by Ctrl-C (128 + SIGINT), as shells report it
_SAID = "roboview_interrupted"


def interrupted(exc: KeyboardInterrupt, message: str) -> KeyboardInterrupt:
    """Say what a run stopped by Ctrl-C kept: `cli_main` then ends with the one line `interrupted: {message}` (no
    traceback; exit status 130). In a run: `except KeyboardInterrupt as exc: raise interrupted(exc, "…")`; the
    innermost message wins."""
    if not hasattr(exc, _SAID):
        setattr(exc, _SAID, message)
    return exc


def cli_main[T, R](
    config_class: type[T],
    run: Callable[[T], R],
    summary: Callable[[T, R], None] | None = None,
    errors: tuple[type[BaseException], ...] = (ValueError,),
    args: list[str] | None = None,
    before_parse: Callable[[], object] | None = None,
    on_interrupt: Callable[[T], str] | None = None,
) -> R:
    """Every pipeline's `main`: environment, parse, run; `errors` (the ones a user can fix) exit
    with their message and no traceback; then `summary(cfg, result)` prints the one-line outcome.
    Ctrl-C ends with one line saying what was kept: the message the run attached (`interrupted`), else
    `on_interrupt(cfg)`, else that rerunning the command starts again; exit status 130."""
    setup_environment()
    cfg = None
    try:
        if before_parse is not None:
            before_parse()
        cfg = parse(config_class, args)
        try:
            result = run(cfg)
        except errors as exc:
            fail(str(exc))
        if summary is not None:
            summary(cfg, result)
        return result
    except KeyboardInterrupt as exc:
        message = getattr(exc, _SAID, None)
        if message is None and on_interrupt is not None and cfg is not None:
            message = on_interrupt(cfg)
        print(
            f"interrupted: {message}" if message else "interrupted; rerun the same command",
            file=sys.stderr,
            flush=True,
        )
        raise SystemExit(INTERRUPTED) from None
