"""Command-line plumbing every RoboView command shares (the verbs, the throughput studies, the integrations' tools):
draccus parsing with readable errors, quiet third-party logs, one `--help` layout for every command
(`roboview.core.cli_help`), and Ctrl-C that ends with one line saying what was kept. `roboview.pipelines._cli` adds
the flag groups the pipelines share."""

from __future__ import annotations

import dataclasses
import difflib
import logging
import os
import sys
import typing
from collections.abc import Callable

import draccus
from draccus.argparsing import ArgumentParser

from roboview.core.cli_fields import is_choice
from roboview.core.cli_flags import comma_lists, renamed_flags
from roboview.core.cli_help import format_help

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
        if not is_choice(kind):
            continue
        for arg in args:
            if arg.startswith(f"--{f.name}.type="):
                name = arg.split("=", 1)[1]
                known = sorted(kind.get_known_choices())
                if name not in known:
                    fail(f"unknown {f.name} type {name!r}; allowed: {', '.join(known)}")


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
