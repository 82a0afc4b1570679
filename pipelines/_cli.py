"""Shared command-line plumbing: draccus parsing with readable errors, quiet third-party logs."""

from __future__ import annotations

import dataclasses
import logging
import os
import sys
import typing
from dataclasses import dataclass
from collections.abc import Callable
from typing import TypeVar

import draccus

T = TypeVar("T")
R = TypeVar("R")

# MuJoCo picks its GL backend when first imported, which the pipelines do before main() runs:
# the headless defaults must be in place as soon as this module is (it is imported first).
os.environ.setdefault("MUJOCO_GL", "egl")
os.environ.setdefault("PYOPENGL_PLATFORM", "egl")


@dataclass
class BenchmarkPath:
    """`--benchmark.path`: the one spelling of a benchmark folder across RoboView's commands."""

    # Benchmark folder written by pipelines.build_benchmark.
    path: str = ""


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


def _list_flags(config_class: type, prefix: str = "") -> set[str]:
    """The --flags of `config_class` (nested configs included) whose field holds a list or tuple."""
    found: set[str] = set()
    hints = typing.get_type_hints(config_class)
    for f in dataclasses.fields(config_class):
        kind = hints.get(f.name)
        if isinstance(kind, type) and dataclasses.is_dataclass(kind) and not issubclass(kind, draccus.ChoiceRegistry):
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


def parse(config_class: type[T], args: list[str] | None = None) -> T:
    """Parse `args` into `config_class`; validation errors exit with the validator's own message."""
    args = comma_lists(config_class, sys.argv[1:] if args is None else list(args))
    _check_choices(config_class, args)
    try:
        return draccus.parse(config_class, args=args)
    except (draccus.utils.ParsingError, draccus.utils.DecodingError) as exc:
        fail(str(_root_cause(exc)))


def setup_environment() -> None:
    """Headless rendering and quiet encoders/progress bars from libraries (ours show progress)."""
    os.environ.setdefault("SVT_LOG", "1")  # SVT-AV1: errors only
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    for noisy in ("libav", "datasets", "httpx", "urllib3"):
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


def cli_main(config_class: type[T], run: Callable[[T], R], summary: Callable[[T, R], None] | None = None,
             errors: tuple[type[BaseException], ...] = (ValueError,), args: list[str] | None = None,
             before_parse: Callable[[], object] | None = None) -> R:
    """Every pipeline's `main`: environment, parse, run; `errors` (the ones a user can fix) exit
    with their message and no traceback; then `summary(cfg, result)` prints the one-line outcome."""
    setup_environment()
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
