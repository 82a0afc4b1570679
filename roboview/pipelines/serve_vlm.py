"""Serve the classic-CV stand-in model over the OpenAI chat-completions protocol (NOT a VLM).

    roboview-serve-vlm --port=8000
    roboview-evaluate --policy.type=vlm_simple \\
        --policy.endpoint.base_url=http://127.0.0.1:8000/v1 \\
        --policy.endpoint.model=roboview-classic-cv-standin ...

The stand-in answers the RoboView agents' prompts (image points, plans, mark choices, scene
parses, fairness yes/no) with classic computer vision on the image it is sent — no simulator state —
so the whole VLM path runs and can be measured on a machine that reaches no VLM. Results obtained
with it are the stand-in's, and are labelled so; point the agents at OpenAI, vLLM or Ollama for a
real VLM's.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

from roboview.pipelines._cli import cli_main
from roboview.policies.vlm.server import start_server
from roboview.policies.vlm.standin import ClassicCVModel


@dataclass
class ServeConfig:
    # Interface to listen on (127.0.0.1: this machine only).
    host: str = "127.0.0.1"
    # TCP port (0: any free port, printed at start).
    port: int = 8000

    def __post_init__(self) -> None:
        if not 0 <= self.port <= 65535:
            raise ValueError(f"--port={self.port} must lie in 0..65535")


def run(cfg: ServeConfig) -> None:
    model = ClassicCVModel()
    try:
        server, url = start_server(model, cfg.host, cfg.port)
    except OSError as exc:
        raise ValueError(
            f"cannot listen on {cfg.host}:{cfg.port}: {exc.strerror}; pick another --port"
        ) from None
    print(
        f"[serve_vlm] model {model.name!r} (classic-CV stand-in, NOT a VLM) at {url}  (Ctrl-C stops)",
        flush=True,
    )
    try:
        while True:
            time.sleep(3600)
    except KeyboardInterrupt:
        server.shutdown()


def main(args: list[str] | None = None) -> None:
    cli_main(ServeConfig, run, args=args)


if __name__ == "__main__":
    main()
