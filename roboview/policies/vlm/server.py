"""A real HTTP server speaking the OpenAI chat-completions protocol, answering with a `model` object.

`roboview.pipelines.serve_vlm` runs it with the classic-CV stand-in (roboview.policies.vlm.standin). The server
decodes the images of the last user message (data URLs, as the `openai` client sends them) and
returns the model's text as the assistant message. Token counts in `usage` are estimates (words of
the prompt and the reply, plus 85 per image, OpenAI's low-detail image cost): a stand-in has no
tokenizer, and a real endpoint reports its own.
"""

from __future__ import annotations

import base64
import io
import json
import threading
import time
import uuid
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any, Protocol

import numpy as np

IMAGE_TOKENS = 85


class Model(Protocol):
    name: str

    def answer(self, prompt: str, images: list[np.ndarray]) -> str: ...


def decode_image(url: str) -> np.ndarray:
    """RGB uint8 array from a base64 data URL (PNG or JPEG)."""
    from PIL import Image

    if not url.startswith("data:"):
        raise ValueError("only data: image URLs are accepted (this server reaches no network)")
    payload = url.split(",", 1)[1]
    return np.asarray(Image.open(io.BytesIO(base64.b64decode(payload))).convert("RGB"))


def last_user_turn(messages: list[dict]) -> tuple[str, list[np.ndarray]]:
    """Text and images of the conversation's user turns (a repair turn follows the original request)."""
    texts, images = [], []
    for message in messages:
        if message.get("role") != "user":
            continue
        content = message.get("content")
        if isinstance(content, str):
            texts.append(content)
            continue
        for part in content or []:
            if part.get("type") == "text":
                texts.append(part["text"])
            elif part.get("type") == "image_url":
                images.append(decode_image(part["image_url"]["url"]))
    return "\n".join(texts), images


def completion(model: str, text: str, prompt_tokens: int) -> dict[str, Any]:
    completion_tokens = len(text.split())
    return {
        "id": f"chatcmpl-{uuid.uuid4().hex[:12]}",
        "object": "chat.completion",
        "created": int(time.time()),
        "model": model,
        "choices": [{"index": 0, "finish_reason": "stop", "message": {"role": "assistant", "content": text}}],
        "usage": {
            "prompt_tokens": prompt_tokens,
            "completion_tokens": completion_tokens,
            "total_tokens": prompt_tokens + completion_tokens,
        },
    }


def make_handler(model: Model) -> type[BaseHTTPRequestHandler]:
    class Handler(BaseHTTPRequestHandler):
        protocol_version = "HTTP/1.1"

        def log_message(self, *args: Any) -> None:  # quiet: one line per request is noise
            pass

        def _send(self, status: int, body: dict) -> None:
            data = json.dumps(body).encode()
            self.send_response(status)
            self.send_header("Content-Type", "application/json")
            self.send_header("Content-Length", str(len(data)))
            self.end_headers()
            self.wfile.write(data)

        def do_GET(self) -> None:
            if self.path.rstrip("/").endswith("/models"):
                self._send(
                    200,
                    {
                        "object": "list",
                        "data": [{"id": model.name, "object": "model", "owned_by": "roboview"}],
                    },
                )
            else:
                self._send(404, {"error": {"message": f"no route {self.path}", "type": "not_found"}})

        def do_POST(self) -> None:
            if not self.path.rstrip("/").endswith("/chat/completions"):
                self._send(404, {"error": {"message": f"no route {self.path}", "type": "not_found"}})
                return
            try:
                body = json.loads(self.rfile.read(int(self.headers.get("Content-Length", 0))))
                prompt, images = last_user_turn(body["messages"])
            except (ValueError, KeyError, TypeError) as exc:
                self._send(
                    400, {"error": {"message": f"bad request: {exc}", "type": "invalid_request_error"}}
                )
                return
            text = model.answer(prompt, images)
            self._send(
                200,
                completion(
                    body.get("model", model.name), text, len(prompt.split()) + IMAGE_TOKENS * len(images)
                ),
            )

    return Handler


def start_server(model: Model, host: str = "127.0.0.1", port: int = 0) -> tuple[ThreadingHTTPServer, str]:
    """Serve `model` on a background thread; returns the server and its base URL (…/v1)."""
    server = ThreadingHTTPServer((host, port), make_handler(model))
    server.daemon_threads = True
    threading.Thread(target=server.serve_forever, name="vlm-server", daemon=True).start()
    return server, f"http://{host}:{server.server_address[1]}/v1"
