"""Real HTTP servers on 127.0.0.1 for the VLM tests: the stand-in model, and a scripted misbehaving one.

`ScriptedServer` answers each chat-completions request with the next step of its script — an HTTP
status, prose, a refusal, a delay, a dropped connection — and then falls back to a model's answer.
It is a real server speaking the real protocol, so the real `openai` client goes through it.
"""

from __future__ import annotations

import json
import threading
import time
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

from roboview.policies.vlm.server import completion, last_user_turn


class ScriptedServer:
    def __init__(self, model, script=()):
        self.model = model
        self.script = list(script)
        self.requests: list[dict] = []
        self.headers: list[dict] = []
        self.active = 0
        self.max_active = 0
        self.delay_s = 0.0
        # Set: every scripted status says when to try again (`retry-after-ms`, as an overloaded endpoint does); the
        # openai client then waits that long instead of its own backoff.
        self.retry_after_ms: int | None = None
        self._lock = threading.Lock()
        self.server = ThreadingHTTPServer(("127.0.0.1", 0), self._handler())
        self.server.daemon_threads = True
        threading.Thread(target=self.server.serve_forever, daemon=True).start()
        self.url = f"http://127.0.0.1:{self.server.server_address[1]}/v1"

    def close(self):
        self.server.shutdown()
        self.server.server_close()

    def _handler(self):
        outer = self

        class Handler(BaseHTTPRequestHandler):
            protocol_version = "HTTP/1.1"

            def log_message(self, *args):
                pass

            def _send(self, status, body):
                data = json.dumps(body).encode()
                self.send_response(status)
                if status >= 400 and outer.retry_after_ms is not None:
                    self.send_header("retry-after-ms", str(outer.retry_after_ms))
                self.send_header("Content-Type", "application/json")
                self.send_header("Content-Length", str(len(data)))
                self.end_headers()
                self.wfile.write(data)

            def do_POST(self):
                body = json.loads(self.rfile.read(int(self.headers.get("Content-Length", 0))))
                with outer._lock:
                    outer.requests.append(body)
                    outer.headers.append(dict(self.headers))
                    step = outer.script.pop(0) if outer.script else None
                    outer.active += 1
                    outer.max_active = max(outer.max_active, outer.active)
                try:
                    time.sleep(outer.delay_s)
                    kind, arg = step if step else ("model", None)
                    if kind == "status":
                        self._send(arg, {"error": {"message": f"scripted {arg}", "type": "scripted"}})
                    elif kind == "sleep":
                        time.sleep(arg)
                        self._send(200, completion("scripted", "{}", 1))
                    elif kind == "drop":
                        self.close_connection = True
                        self.connection.shutdown(2)
                    elif kind == "text":
                        self._send(200, completion("scripted", arg, 1))
                    elif kind == "refusal":
                        body = completion("scripted", "", 1)
                        body["choices"][0]["message"] = {"role": "assistant", "content": None, "refusal": arg}
                        self._send(200, body)
                    else:
                        prompt, images = last_user_turn(body["messages"])
                        self._send(200, completion(outer.model.name, outer.model.answer(prompt, images), 10))
                finally:
                    with outer._lock:
                        outer.active -= 1

        return Handler
