"""One client for OpenAI-compatible chat completions with images: OpenAI, vLLM, Ollama, or the stand-in.

Built on the official `openai` package. What it adds for a benchmark:

- **Deterministic and free on rerun.** Temperature 0, and a disk cache keyed by SHA-256 of (model,
  messages with the image bytes): asking again costs nothing and returns exactly the same answer.
- **Strict JSON.** Every answer must parse as JSON and pass the caller's check; otherwise one repair
  request quotes the error, and a second bad answer is a `VLMAnswerError` (the episode fails with it).
- **Transient failures are retried**: the `openai` client retries 429, 5xx, timeouts and dropped
  connections with exponential backoff (`max_retries`); what is still failing after that becomes a
  `TransientPolicyError`, which the evaluator retries twice more before recording a failed episode.
- **Bounded load.** At most `max_in_flight` requests to one endpoint across all worker processes of
  a machine (file-lock slots), so ten render workers never open ten streams to a rate-limited API.
- **Accounting.** Requests, cache hits, prompt / completion tokens and latency accumulate per episode
  (`take_stats`) and land in the episode rows; the report sums them.
- **No secrets in files.** The config names the *environment variable* holding the API key.
"""

from __future__ import annotations

import base64
import fcntl
import hashlib
import io
import json
import os
import re
import tempfile
import time
from collections.abc import Callable
from contextlib import contextmanager
from dataclasses import dataclass, field, fields
from pathlib import Path
from typing import Any

import numpy as np

from roboview.core.files import cache_dir
from roboview.policies.errors import TransientPolicyError

STAT_KEYS = ("vlm_requests", "vlm_cache_hits", "vlm_prompt_tokens", "vlm_completion_tokens", "vlm_latency_s")
REPAIR = (
    "Your previous reply could not be used: {error}. Reply again with only the JSON value the "
    "instructions ask for, nothing before or after it."
)


class VLMAnswerError(RuntimeError):
    """The model's answer was unusable (not JSON, wrong shape, a refusal) even after one repair request."""


def default_cache_dir() -> str:
    """Where VLM answers are cached unless told otherwise: the XDG cache folder, as Hugging Face's caches."""
    return str(cache_dir("vlm"))


@dataclass(frozen=True)
class Endpoint:
    """A VLM endpoint: an OpenAI-compatible chat-completions server, a model on it, and how to ask it.
    Every command that asks a VLM nests one (`--policy.endpoint.*`, `--sgl.endpoint.*`, `--vlm_screen.*`)."""

    # Base URL of the API: https://api.openai.com/v1, http://localhost:8000/v1 (vLLM),
    # http://localhost:11434/v1 (Ollama), or roboview.pipelines.serve_vlm's stand-in.
    base_url: str = "http://127.0.0.1:8000/v1"
    # Model name on that endpoint (gpt-4o, qwen-vl-max, Qwen/Qwen2.5-VL-7B-Instruct, ...).
    model: str = ""
    # Name of the environment variable holding the API key (the key itself never goes in a file); unset:
    # "EMPTY", which local servers accept.
    api_key_env: str = "OPENAI_API_KEY"
    # Seconds per request.
    timeout_s: float = 60.0
    # Retries of a request answered 429 / 5xx or timed out, with exponential backoff, before it fails.
    max_retries: int = 4
    # Requests in flight to this endpoint at once, across every worker process on this machine.
    max_in_flight: int = 4
    # Answer cache: a rerun asks nothing twice ("" turns it off); default $XDG_CACHE_HOME/roboview/vlm.
    cache_dir: str = field(default_factory=default_cache_dir)

    def validate(self, flag: str = "") -> None:
        """ValueError naming the bad setting (as `flag` + its name, e.g. `--policy.endpoint.model`)."""
        if not re.match(r"^https?://", self.base_url):
            raise ValueError(
                f"{flag}base_url={self.base_url!r} must be an http(s) URL of an "
                "OpenAI-compatible API (e.g. https://api.openai.com/v1 or "
                "http://127.0.0.1:8000/v1)"
            )
        if not self.model:
            raise ValueError(
                f"{flag}model is empty: name the model to ask (e.g. gpt-4o, Qwen/Qwen2.5-VL-7B-Instruct)"
            )
        if self.timeout_s <= 0 or self.max_retries < 0 or self.max_in_flight < 1:
            raise ValueError(
                f"{flag}timeout_s={self.timeout_s}, {flag}max_retries={self.max_retries}, "
                f"{flag}max_in_flight={self.max_in_flight}: need > 0, ≥ 0 and ≥ 1"
            )


# The fields of an Endpoint, which configs that once declared them flat still accept flat on the command
# line (`--policy.model` → `--policy.endpoint.model`, with a deprecation line).
ENDPOINT_FIELDS = tuple(f.name for f in fields(Endpoint))


def endpoint_aliases(*names: str) -> dict[str, str]:
    """Old flat flag names → their place in a config's nested `endpoint` (a config's `flag_aliases`)."""
    unknown = [n for n in names if n not in ENDPOINT_FIELDS]
    if unknown:
        raise ValueError(f"not Endpoint fields: {unknown}; allowed: {', '.join(ENDPOINT_FIELDS)}")
    return {name: f"endpoint.{name}" for name in names or ENDPOINT_FIELDS}


def png_data_url(image: np.ndarray) -> str:
    """An RGB uint8 image as a base64 PNG data URL (lossless: the cache key sees every pixel)."""
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(image)).save(buf, format="PNG", compress_level=1)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode()


def user_message(text: str, images: list[np.ndarray]) -> dict:
    content: list[dict] = [{"type": "text", "text": text}]
    content += [{"type": "image_url", "image_url": {"url": png_data_url(img)}} for img in images]
    return {"role": "user", "content": content}


def parse_json(text: str | None) -> Any:
    """The JSON value in a reply, tolerating a ```json fence around it; ValueError otherwise."""
    if text is None or not text.strip():
        raise ValueError("the reply was empty")
    body = text.strip()
    fence = re.match(r"^```(?:json)?\s*(.*?)\s*```$", body, re.S)
    if fence:
        body = fence.group(1)
    try:
        return json.loads(body)
    except json.JSONDecodeError as exc:
        snippet = body[:80].replace("\n", " ")
        raise ValueError(f"the reply is not JSON ({exc.msg} at char {exc.pos}): {snippet!r}") from None


class _Slots:
    """At most n holders across processes: n lock files under the temp dir, one per slot."""

    def __init__(self, key: str, n: int) -> None:
        folder = (
            Path(tempfile.gettempdir())
            / f"roboview-vlm-slots-{hashlib.sha256(key.encode()).hexdigest()[:12]}"
        )
        folder.mkdir(parents=True, exist_ok=True)
        self.paths = [folder / f"slot{i}.lock" for i in range(n)]

    @contextmanager
    def hold(self):
        while True:
            for path in self.paths:
                f = path.open("a")
                try:
                    fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
                except BlockingIOError:
                    f.close()
                    continue
                try:
                    yield
                finally:
                    fcntl.flock(f, fcntl.LOCK_UN)
                    f.close()
                return
            time.sleep(0.02)


class VLMClient:
    """Ask an OpenAI-compatible endpoint for JSON about images; cached, retried, bounded, counted."""

    def __init__(self, endpoint: Endpoint) -> None:
        import openai

        endpoint.validate()
        self.endpoint = endpoint
        self._openai = openai
        self._client = openai.OpenAI(
            base_url=endpoint.base_url,
            api_key=os.environ.get(endpoint.api_key_env) or "EMPTY",
            timeout=endpoint.timeout_s,
            max_retries=endpoint.max_retries,
        )
        self._slots = _Slots(endpoint.base_url, endpoint.max_in_flight)
        self._cache = Path(endpoint.cache_dir) if endpoint.cache_dir else None
        self.stats = dict.fromkeys(STAT_KEYS, 0)

    def take_stats(self) -> dict[str, float]:
        """The counters since the last call (one episode's), then zeroed."""
        out, self.stats = self.stats, dict.fromkeys(STAT_KEYS, 0)
        out["vlm_latency_s"] = round(float(out["vlm_latency_s"]), 4)
        return out

    # -- cache ---------------------------------------------------------------------------------
    def _key(self, messages: list[dict]) -> str:
        payload = json.dumps({"model": self.endpoint.model, "messages": messages}, sort_keys=True)
        return hashlib.sha256(payload.encode()).hexdigest()

    def _cache_path(self, key: str) -> Path | None:
        return None if self._cache is None else self._cache / key[:2] / f"{key}.json"

    def _cached(self, key: str) -> dict | None:
        path = self._cache_path(key)
        if path is None or not path.is_file():
            return None
        try:
            return json.loads(path.read_text())
        except (OSError, json.JSONDecodeError):
            return None  # a torn write: ask again

    def _store(self, key: str, entry: dict) -> None:
        path = self._cache_path(key)
        if path is None:
            return
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_text(json.dumps(entry))
        tmp.replace(path)

    # -- asking --------------------------------------------------------------------------------
    def _complete(self, messages: list[dict]) -> str:
        o = self._openai
        start = time.perf_counter()
        try:
            with self._slots.hold():
                response = self._client.chat.completions.create(
                    model=self.endpoint.model, messages=messages, temperature=0
                )
        except (o.RateLimitError, o.InternalServerError, o.APITimeoutError, o.APIConnectionError) as exc:
            raise TransientPolicyError(f"{self.endpoint.base_url}: {type(exc).__name__}: {exc}") from exc
        except o.APIStatusError as exc:  # 400, 401, 404, ...: asking again will not help
            raise VLMAnswerError(
                f"{self.endpoint.base_url} answered HTTP {exc.status_code}: {exc.message}"
            ) from exc
        finally:
            self.stats["vlm_latency_s"] += time.perf_counter() - start
        self.stats["vlm_requests"] += 1
        usage = getattr(response, "usage", None)
        if usage is not None:
            self.stats["vlm_prompt_tokens"] += int(usage.prompt_tokens or 0)
            self.stats["vlm_completion_tokens"] += int(usage.completion_tokens or 0)
        if not response.choices:
            raise VLMAnswerError(f"{self.endpoint.base_url} returned no choices")
        choice = response.choices[0]
        refusal = getattr(choice.message, "refusal", None)
        if refusal:
            raise VLMAnswerError(f"the model refused: {refusal}")
        return choice.message.content or ""

    def ask_json(
        self, prompt: str, images: list[np.ndarray], check: Callable[[Any], Any] | None = None
    ) -> Any:
        """The checked JSON answer to `prompt` about `images` (`check` returns the value or raises ValueError)."""
        messages = [user_message(prompt, images)]
        key = self._key(messages)
        hit = self._cached(key)
        if hit is not None:
            self.stats["vlm_cache_hits"] += 1
            return check(hit["answer"]) if check else hit["answer"]
        text = self._complete(messages)
        try:
            answer = parse_json(text)
            value = check(answer) if check else answer
        except ValueError as first:
            repair = [
                *messages,
                {"role": "assistant", "content": text},
                {"role": "user", "content": REPAIR.format(error=first)},
            ]
            text = self._complete(repair)
            try:
                answer = parse_json(text)
                value = check(answer) if check else answer
            except ValueError as second:
                raise VLMAnswerError(f"unusable answer after one repair request: {second}") from None
        self._store(key, {"model": self.endpoint.model, "answer": answer, "text": text})
        return value
