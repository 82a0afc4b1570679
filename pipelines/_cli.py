"""Shared command-line plumbing: draccus parsing with readable errors, quiet third-party logs."""

from __future__ import annotations

import logging
import os
import sys
from typing import TypeVar

import draccus

T = TypeVar("T")

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


def parse(config_class: type[T], args: list[str] | None = None) -> T:
    """Parse `args` into `config_class`; validation errors exit with the validator's own message."""
    try:
        return draccus.parse(config_class, args=args)
    except draccus.utils.ParsingError as exc:
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
    except ImportError:
        pass
