"""Headless Chromium driven over the DevTools protocol (websockets), for tests of report.html.

`load_page(path)` opens a file in a fresh headless Chromium, waits for the load event and returns what the page
raised (console errors, uncaught exceptions, failed loads), each image's on-screen box and a full-page screenshot.
"""

from __future__ import annotations

import base64
import io
import json
import shutil
import subprocess
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from PIL import Image
from websockets.sync.client import connect


def chromium_binary() -> str | None:
    for name in ("chromium", "chromium-browser", "google-chrome"):
        if found := shutil.which(name):
            return found
    return None


@dataclass
class Page:
    errors: list[str]  # console errors, uncaught exceptions and failed loads, as Chromium reported them
    images: list[dict]  # {alt, x, y, width, height, natural_width} per <img>, in page coordinates (CSS px)
    screenshot: np.ndarray  # the whole page, H × W × 3 uint8
    # The page's scroll width and each table's right edge (CSS px): what overflows the window.
    layout: dict = None  # type: ignore[assignment]
    # What each expression given to load_page(scripts=...) returned, in order (run after the screenshot).
    evaluated: list = None  # type: ignore[assignment]


class _DevTools:
    def __init__(self, ws) -> None:
        self.ws = ws
        self.next_id = 0
        self.events: list[dict] = []

    def call(self, method: str, session: str | None = None, timeout: float = 30, **params) -> dict:
        self.next_id += 1
        message = {"id": self.next_id, "method": method, "params": params}
        if session:
            message["sessionId"] = session
        self.ws.send(json.dumps(message))
        deadline = time.monotonic() + timeout
        while True:
            reply = json.loads(self.ws.recv(timeout=max(0.1, deadline - time.monotonic())))
            if reply.get("id") == self.next_id:
                if "error" in reply:
                    raise RuntimeError(f"{method}: {reply['error']}")
                return reply["result"]
            self.events.append(reply)

    def wait_for(self, event: str, timeout: float = 30) -> None:
        if any(e.get("method") == event for e in self.events):
            return
        deadline = time.monotonic() + timeout
        while True:
            message = json.loads(self.ws.recv(timeout=max(0.1, deadline - time.monotonic())))
            self.events.append(message)
            if message.get("method") == event:
                return


def _errors(events: list[dict]) -> list[str]:
    found = []
    for e in events:
        method, params = e.get("method"), e.get("params", {})
        if method == "Runtime.exceptionThrown":
            found.append(
                "exception: " + params["exceptionDetails"].get("exception", {}).get("description", "")
                or params["exceptionDetails"].get("text", "")
            )
        elif method == "Runtime.consoleAPICalled" and params.get("type") in ("error", "assert"):
            found.append(
                "console: " + " ".join(str(a.get("value", a.get("description", ""))) for a in params["args"])
            )
        elif method == "Log.entryAdded" and params["entry"]["level"] == "error":
            found.append(
                f"{params['entry']['source']}: {params['entry']['text']} {params['entry'].get('url', '')}"
            )
    return found


_IMAGES_JS = """JSON.stringify(Array.from(document.images).map(i => { const r = i.getBoundingClientRect();
  return {alt: i.alt, x: r.x + scrollX, y: r.y + scrollY, width: r.width, height: r.height,
          natural_width: i.complete ? i.naturalWidth : 0}; }))"""


_LAYOUT_JS = """JSON.stringify({page: document.documentElement.scrollWidth,
  tables: Array.from(document.querySelectorAll('table')).map(t => t.getBoundingClientRect().right + scrollX)})"""


def load_page(path: Path, width: int = 1200, timeout: float = 60, scripts: tuple[str, ...] = ()) -> Page:
    binary = chromium_binary()
    if binary is None:
        raise FileNotFoundError("no chromium on PATH (make sysdeps installs Debian's chromium)")
    with tempfile.TemporaryDirectory(ignore_cleanup_errors=True) as profile:  # chromium may still be writing
        proc = subprocess.Popen(
            [
                binary,
                "--headless",
                "--no-sandbox",
                "--disable-gpu",
                "--hide-scrollbars",
                "--remote-debugging-port=0",
                f"--user-data-dir={profile}",
                "about:blank",
            ],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
        )
        try:
            port_file = Path(profile) / "DevToolsActivePort"
            deadline = time.monotonic() + timeout
            while not (port_file.is_file() and len(port_file.read_text().splitlines()) >= 2):
                if proc.poll() is not None or time.monotonic() > deadline:
                    raise RuntimeError(f"chromium did not open its DevTools port (exit code {proc.poll()})")
                time.sleep(0.1)
            port, browser_path = port_file.read_text().splitlines()[:2]
            with connect(f"ws://127.0.0.1:{port}{browser_path}", max_size=None, open_timeout=20) as ws:
                tools = _DevTools(ws)
                target = tools.call("Target.createTarget", url="about:blank")["targetId"]
                session = tools.call("Target.attachToTarget", targetId=target, flatten=True)["sessionId"]
                for domain in ("Page", "Runtime", "Log"):
                    tools.call(f"{domain}.enable", session)
                tools.call(
                    "Emulation.setDeviceMetricsOverride",
                    session,
                    width=width,
                    height=900,
                    deviceScaleFactor=1,
                    mobile=False,
                )
                tools.call("Page.navigate", session, url=Path(path).resolve().as_uri())
                tools.wait_for("Page.loadEventFired", timeout)
                images = json.loads(
                    tools.call("Runtime.evaluate", session, expression=_IMAGES_JS, returnByValue=True)[
                        "result"
                    ]["value"]
                )
                layout = json.loads(
                    tools.call("Runtime.evaluate", session, expression=_LAYOUT_JS, returnByValue=True)[
                        "result"
                    ]["value"]
                )
                size = tools.call("Page.getLayoutMetrics", session)["cssContentSize"]
                shot = tools.call(
                    "Page.captureScreenshot",
                    session,
                    timeout,
                    format="png",
                    captureBeyondViewport=True,
                    clip={"x": 0, "y": 0, "width": width, "height": size["height"], "scale": 1},
                )
                evaluated = [
                    tools.call("Runtime.evaluate", session, expression=js, returnByValue=True)["result"].get(
                        "value"
                    )
                    for js in scripts
                ]
                time.sleep(0.2)  # late console messages
                tools.call("Runtime.evaluate", session, expression="1")
                errors = _errors(tools.events)
        finally:
            proc.terminate()
            try:
                proc.wait(10)
            except subprocess.TimeoutExpired:
                proc.kill()
    pixels = np.asarray(Image.open(io.BytesIO(base64.b64decode(shot["data"]))).convert("RGB"))
    return Page(errors, images, pixels, layout, evaluated)
