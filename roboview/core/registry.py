"""The live registries' shape (`Registry`) and the discovery that fills them (`discover`).

Every world's wing registers what it declares — its factors, its `World`, its tasks, its presets — when its modules
are imported. Which modules those are is data, not a list in the house: the modules named under the `roboview.tasks`
entry-point group (RoboView's own in its pyproject.toml, another package's in its own). `discover()` imports each of
them once, and every registry runs it before it is read, so a registry read in any process (a fork server's worker, a
spawned one, a Ray actor) holds every world's entries, whatever that process imported first. Registering never
discovers: a wing's module registers into the registries while it is imported.

A registry with an `origin` lists its entries in the order of the modules they come from (`rank`): RoboView's entry
points in the order of their names, then every other distribution's, then anything else; one module's entries in the
order it registered them. The listing is therefore the same whichever wing a process imported first.

A registry read while a wing's module is still being imported (a suite preset checked at its registration) finds the
wings before it and the house; `discover` goes on with the rest at the next read once that module has finished.
"""

from __future__ import annotations

import importlib
import importlib.metadata
import sys
import threading
from collections.abc import Callable, Iterator, Mapping
from functools import cache
from types import MappingProxyType
from typing import TypeVar

ENTRY_POINT_GROUP = "roboview.tasks"
DISTRIBUTION = "roboview"
INSTALL = "make install (or: pip install -e .)"

V = TypeVar("V")

_LOCK = threading.RLock()
_STATE = {"done": False, "running": False}


def distribution_name(entry: importlib.metadata.EntryPoint) -> str:
    dist = entry.dist
    return "" if dist is None else dist.name.lower().replace("-", "_")


@cache
def wing_modules() -> tuple[str, ...]:
    """The modules named under the `roboview.tasks` entry-point group, in the order they are imported and their
    entries listed: RoboView's own by entry name (its pyproject.toml numbers them), then each other distribution's,
    by distribution and entry name."""
    entries = importlib.metadata.entry_points(group=ENTRY_POINT_GROUP)
    ordered = sorted(
        entries, key=lambda e: (distribution_name(e) != DISTRIBUTION, distribution_name(e), e.name)
    )
    if not any(distribution_name(e) == DISTRIBUTION for e in ordered):
        raise RuntimeError(
            f"RoboView's package metadata names no `{ENTRY_POINT_GROUP}` entry point, so no task or world registers: "
            f"reinstall it from its pyproject.toml ({INSTALL})"
        )
    return tuple(dict.fromkeys(e.module for e in ordered))


def initializing(module: str) -> bool:
    """Whether `module`'s import has begun and not finished (its body is running, in this thread or another)."""
    spec = getattr(sys.modules.get(module), "__spec__", None)
    return bool(getattr(spec, "_initializing", False))


def discover() -> None:
    """Import every wing module (`wing_modules`) once, in order. A call inside the discovery (a wing reading a registry
    while it is imported) returns at once; a call while a wing module is being imported imports the ones before it
    and returns, and the next call goes on from there. Another thread's call waits for this one."""
    if _STATE["done"]:
        return
    with _LOCK:
        if _STATE["done"] or _STATE["running"]:
            return
        _STATE["running"] = True
        try:
            for module in wing_modules():
                if initializing(module):
                    return
                importlib.import_module(module)
            _STATE["done"] = True
        finally:
            _STATE["running"] = False


def rank(module: str) -> int:
    """The place of `module`'s entries in a listing: the index of the wing module it is, else of the first one in its
    package (`roboview.libero` and `roboview.libero.presets` rank with `roboview.libero.task`); after them all if
    neither."""
    modules = wing_modules()
    if module in modules:
        return modules.index(module)
    for i, wing in enumerate(modules):
        package = wing.rpartition(".")[0]
        if package and (module == package or module.startswith(package + ".")):
            return i
    return len(modules)


class Registry(Mapping[str, V]):
    """name → entry: filled by `add` as the wings register, discovered (`discover`) before every read. With `origin`
    (entry → the module it comes from), iterated in the order of `rank`, then of registration."""

    def __init__(self, kind: str, origin: Callable[[V], str] | None = None) -> None:
        self.kind = kind
        self._origin = origin
        self._entries: dict[str, V] = {}
        self._order: tuple[str, ...] | None = None

    def add(self, name: str, entry: V) -> V:
        """Register `entry` under `name` (once); no discovery."""
        if name in self._entries:
            raise ValueError(f"{self.kind} {name!r} is already registered")
        self._entries[name] = entry
        self._order = None
        return entry

    def remove(self, name: str) -> None:
        """Forget `name` (a test's throwaway entry)."""
        self._entries.pop(name, None)
        self._order = None

    @property
    def registered(self) -> Mapping[str, V]:
        """The entries registered so far, without discovery: what a registration's own checks read."""
        return MappingProxyType(self._entries)

    def names(self) -> tuple[str, ...]:
        if self._order is None:
            names = tuple(self._entries)
            if self._origin is not None:
                seq = {name: i for i, name in enumerate(names)}
                names = tuple(sorted(names, key=lambda n: (rank(self._origin(self._entries[n])), seq[n])))
            self._order = names
        return self._order

    def __getitem__(self, name: str) -> V:
        discover()
        return self._entries[name]

    def __contains__(self, name: object) -> bool:
        discover()
        return name in self._entries

    def __iter__(self) -> Iterator[str]:
        discover()
        return iter(self.names())

    def __len__(self) -> int:
        discover()
        return len(self._entries)

    def __repr__(self) -> str:
        return f"Registry({self.kind!r}, {list(self)!r})"
