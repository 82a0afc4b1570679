"""Library errors speak Python; the command-line layer says which flag they were about.

Library functions raise `ValueError`s that name the bad value and what is allowed ("dataset root
/x is a file; give a folder"). A pipeline's config or `run` wraps the call that consumes a flag in
`flag_errors("--dataset.root")`, which re-raises the same exception type with the flag in front:
"--dataset.root: dataset root /x is a file; …".
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager


class WorldMissing(ImportError):
    """A world's package or assets are absent (LIBERO's, LIBERO-plus's); the message names what is missing and how to
    install it, in one line a verb prints as it is."""


@contextmanager
def flag_errors(flag: str) -> Iterator[None]:
    """Prefix a ValueError raised inside the block with the command-line `flag` it concerns."""
    try:
        yield
    except ValueError as exc:
        message = f"{flag}: {exc}"
        try:
            translated = type(exc)(message)
        except TypeError:  # an exception type with its own constructor signature
            translated = ValueError(message)
        raise translated from None  # the CLI prints the root cause: this one
