"""Spawned pool workers end with their parent.

A `multiprocessing` / `concurrent.futures` worker blocks on its task queue; when the parent is
killed with SIGKILL nobody closes that queue and the worker (≈ 640 MB with a renderer and a policy)
lingers forever. Every pool initializer calls `exit_with_parent()`: a daemon thread notices that the
process was re-parented (its parent died) and ends it.
"""

from __future__ import annotations

import os
import threading
import time

POLL_S = 1.0


def exit_with_parent(poll_s: float = POLL_S) -> None:
    parent = os.getppid()

    def watch() -> None:
        while True:
            time.sleep(poll_s)
            if os.getppid() != parent:
                os._exit(1)  # no cleanup to run: the parent that wanted the results is gone

    threading.Thread(target=watch, name="exit-with-parent", daemon=True).start()
