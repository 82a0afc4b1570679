"""A build's instances rendered on a Ray cluster: `num_workers` renderer actors (one CPU each, spread over the
nodes), each handed one world's instances per call, as the local worker pool is.

    roboview-build-benchmark --preset=libero --ray_address=HEAD:6379 --num_workers=32 --output_dir=DIR

An instance's record is a function of the instance alone (its reset is seeded; LIBERO's model is reset in place,
bit-identical to a hard reset), so the manifest is the local build's whichever node renders what. A node lost
mid-build fails the build (rerun it); it is not resumed.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from typing import Any


def imap_ray(
    address: str, num_workers: int, args: tuple, batches: Iterable[list[Any]]
) -> Iterator[list[dict]]:
    """`InstanceRenderer(*args).records(batch)` of every batch on the cluster at `address`, in order."""
    import ray

    from roboview.benchmark.render import InstanceRenderer
    from roboview.core.ray_cluster import connect

    connect(address, num_workers, "--ray_address")
    actor_cls = ray.remote(num_cpus=1)(InstanceRenderer).options(scheduling_strategy="SPREAD")
    actors = [actor_cls.remote(*args) for _ in range(num_workers)]
    # Ray runs an actor's calls in the order they were submitted: round-robin, at most two in flight per actor.
    pending: list = []
    batches = iter(batches)
    try:
        for i, batch in enumerate(batches):
            pending.append(actors[i % num_workers].records.remote(batch))
            if len(pending) >= 2 * num_workers:
                yield ray.get(pending.pop(0))
        while pending:
            yield ray.get(pending.pop(0))
    finally:
        for actor in actors:
            ray.kill(actor)
