"""Serve a RoboView policy over openpi's websocket protocol, batching requests across connections.

    roboview-serve-policy --policy.type=lerobot --policy.path=outputs/train/checkpoints/last \\
        --host=0.0.0.0 --port=8000
    # on each render machine:
    roboview-evaluate --policy.type=openpi --policy.url=ws://gpu-host:8000 \\
        --policy.cameras=left_top,wrist --policy.image_size=96 ...

Any openpi client works against it unchanged (openpi-client's `WebsocketClientPolicy`, openpi's own
example loops, other harnesses): on connect it sends its metadata, each request is one observation in
the `--obs_format` layout (see roboview.policies.serving.openpi_wire), each answer `{"actions": (H, 8), "server_timing":
{...}}`, an error is a traceback text frame then close code 1011, and `GET /healthz` answers `OK`.

**Batching across connections.** A chunked LeRobot checkpoint (act, pi0, pi05, smolvla, xvla) is built
once with one slot per connection: requests that arrive while the model is busy, or within `--gather_ms`
of the first, go through one forward pass together, so N render workers on other machines share one
model (openpi's own server answers one request at a time). Each request is stateless: the answer is
the next `n_action_steps` actions for that observation and prompt; the client keeps the queue.

Other policy types (vision, VLM agents, checkpoints that keep observation history) get one policy per
connection, answer one action per request, and are reset when a new episode starts: RoboView's client
sends the episode (task, seed, camera calibration) with its first request; another client's new prompt
starts a new episode without calibration, which policies that need it refuse by name. The scripted
`expert` reads the simulator's state and cannot be served.

`--server=openpi` serves the same policy through openpi-server's own `WebsocketPolicyServer` instead
(one request at a time): the reference the batching is measured against.
"""

from __future__ import annotations

import asyncio
import os
import threading

from roboview.pipelines._cli import cli_main
from roboview.policies.serving.batching import (
    BatchingServer,
    OneRequestPolicy,
    PolicyService,
    ServeConfig,
    stop_on_sigterm,
)
from roboview.policies.serving.openpi_wire import ROBOVIEW_KEY
from roboview.policies.types import load_policy_types


def run(cfg: ServeConfig) -> None:
    stop_on_sigterm()
    service = PolicyService(cfg)
    info = service.metadata[ROBOVIEW_KEY]
    mode = (
        "one request at a time (openpi-server)"
        if cfg.server == "openpi"
        else "batched across connections"
        if service.batched is not None
        else "one policy per connection"
    )
    what = f"{info['policy']} ({cfg.obs_format} layout, {service.image_size}² images, {mode}, horizon {service.horizon})"
    try:
        if cfg.server == "openpi":
            from openpi_server.websocket_policy_server import WebsocketPolicyServer

            server = WebsocketPolicyServer(OneRequestPolicy(service), cfg.host, cfg.port, service.metadata)
            print(f"[serve_policy] {what} at ws://{cfg.host}:{cfg.port}  (Ctrl-C stops)", flush=True)
            server.serve_forever()
        else:
            bound: list[int] = []
            ready = threading.Event()

            def announce() -> None:
                ready.wait()
                print(f"[serve_policy] {what} at ws://{cfg.host}:{bound[0]}  (Ctrl-C stops)", flush=True)

            threading.Thread(target=announce, daemon=True).start()
            server = BatchingServer(
                service, cfg.max_clients, cfg.gather_ms / 1000, os.environ.get(cfg.api_key_env)
            )
            asyncio.run(server.serve(cfg.host, cfg.port, ready, bound))
    except KeyboardInterrupt:
        pass
    except OSError as exc:
        raise ValueError(
            f"cannot listen on {cfg.host}:{cfg.port}: {exc.strerror}; pick another --port"
        ) from None
    finally:
        print(
            f"[serve_policy] {service.requests} requests in {service.forward_passes} forward passes",
            flush=True,
        )
        service.close()


def main(args: list[str] | None = None) -> None:
    cli_main(ServeConfig, run, args=args, before_parse=load_policy_types)


if __name__ == "__main__":
    main()
