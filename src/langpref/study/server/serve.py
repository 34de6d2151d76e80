"""`langpref study serve`: load the model and data, open (or create) the database, make videos ahead, serve.

The database remembers the protocol (`StudyConfig`), the model and the dataset it was created with; a later start
on the same database continues the same study and refuses a different model, dataset or protocol (pass a new
`--db` for a new study), so stored answers always mean what they meant.
"""

from __future__ import annotations

import hashlib
import os
import secrets
import signal
import socket
import sys
import threading
from dataclasses import asdict, fields
from pathlib import Path
from typing import Any

from langpref import __version__
from langpref.errors import LangprefError
from langpref.feedback.kind import get_kind
from langpref.study.protocol import db as sdb
from langpref.study.protocol.config import StudyConfig
from langpref.study.server.app import create_app
from langpref.study.server.hook import ShowHook
from langpref.study.server.settings import ServeConfig
from langpref.study.server.state import StudyApp
from langpref.study.server.videos import VideoCache
from langpref.study.session.engine import StudyEngine
from langpref.study.session.generated import Generator, check_generation


def _file_sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest() if path.is_file() else ""


def resolve_study_config(db_path: str | Path, overrides: dict[str, Any]) -> StudyConfig:
    """The protocol of the study in `db_path` (its stored one when it exists) with `overrides` (None = unset).

    An override that contradicts a stored protocol is an error: a study keeps one protocol for its lifetime.
    """
    given = {k: v for k, v in overrides.items() if v is not None}
    path = Path(db_path)
    if path.is_file():
        conn = sdb.connect(path)
        try:
            meta = sdb.read_meta(conn) if sdb.schema_version(conn) else {}
        except Exception:  # noqa: BLE001 (init_db reports an unusable file with a clear message)
            meta = {}
        finally:
            conn.close()
        if "study" in meta:
            stored = StudyConfig.from_dict(meta["study"])
            for key, value in given.items():
                if getattr(stored, key) != value:
                    flag = "--" + key.replace("_", "-")
                    raise LangprefError(
                        f"{path} holds a study made with {flag} {getattr(stored, key)}, not {value}; "
                        f"drop {flag} to continue it, or pass a new --db for a new study"
                    )
            return stored
    known = {f.name for f in fields(StudyConfig)}
    cfg = StudyConfig(**{k: v for k, v in given.items() if k in known})
    cfg.validate()
    return cfg


def build_state(
    cfg: ServeConfig, engine: StudyEngine | None = None, progress: bool = True, admin_token: str | None = None
) -> StudyApp:
    """Engine, database (created or checked), video cache, `--on-show` hook and (`--improve-candidates generated`)
    Study 1's generated candidates of a study."""
    cfg.validate()
    check_db_path(cfg.db)
    generating = cfg.study.improve_candidates == "generated"
    if generating:
        check_generation(cfg.data)  # before the model is loaded: a recorded task fails in a second
    engine = engine or StudyEngine.load(cfg.model, cfg.data, cfg.study)
    model_dir, data_dir = Path(cfg.model).resolve(), Path(cfg.data).resolve()
    meta = {
        "study": cfg.study.to_dict(),
        "model": str(model_dir),
        "model_sha256": _file_sha(model_dir / "config.json"),
        "data": str(data_dir),
        "data_sha256": _file_sha(data_dir / "meta.json"),
        "env": engine.env,
        "video": asdict(cfg.video),
        "langpref_version": __version__,
    }
    stored = sdb.init_db(cfg.db, meta)
    # a protocol stored before an option existed has that option's default (what the study then did)
    if StudyConfig.from_dict(stored.get("study") or {}).to_dict() != cfg.study.to_dict() or "study" not in stored:
        raise LangprefError(
            f"{cfg.db} holds a study with protocol {stored.get('study')}; pass a new --db for another protocol"
        )
    for key, what in (("model_sha256", "model"), ("data_sha256", "dataset")):
        if stored.get(key) != meta[key]:
            raise LangprefError(
                f"{cfg.db} belongs to a study run with another {what} ({stored.get(key[:-7])}); pass "
                f"that {what} again, or a new --db for a new study"
            )
    sdb.add_kind_tables(cfg.db, tuple(get_kind(k) for k in cfg.study.kinds))
    videos = VideoCache(cfg.data, cfg.videos or f"{cfg.db}.videos", cfg.video, engine.study, progress=progress)
    generated = None
    if generating:
        store = cfg.generated or f"{cfg.db}.generated"
        generated = Generator(engine, cfg.study, cfg.db, store, cfg.model, cfg.data)
        videos.attach(generated)
    hook = ShowHook(cfg.on_show, engine.dataset, cfg.on_show_timeout) if cfg.on_show else None
    if hook is not None and generated is not None:
        hook.attach(generated)
    token = admin_token or cfg.resolve_admin_token() or secrets.token_urlsafe(24)
    return StudyApp(
        cfg.db,
        engine,
        videos,
        token,
        cfg.study,
        hook=hook,
        allowed_origins=cfg.allowed_origins,
        generated=generated,
        allowed_hosts=cfg.allowed_hosts,
        bind_host=cfg.host,
        trusted_proxies=cfg.trusted_proxies,
        signups_per_client=cfg.signups_per_client,
    )


def bind(host: str, port: int) -> socket.socket:
    """A listening socket (port 0: any free port), with a clear error when the port is taken."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    sock = socket.socket(family, socket.SOCK_STREAM, socket.IPPROTO_TCP)  # asyncio sets TCP_NODELAY only then
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((host, port))
    except OSError as exc:
        sock.close()
        raise LangprefError(f"cannot listen on {host}:{port} ({exc.strerror}); pass another --port or --host") from None
    sock.listen(2048)
    sock.set_inheritable(True)
    return sock


def _uvicorn_server(app, log_level: str = "warning"):
    import uvicorn

    from langpref.study.server.transport import OneSendH11Protocol

    class StudyServer(uvicorn.Server):
        def handle_exit(self, sig, frame) -> None:  # SIGTERM, SIGINT: the requests waiting for a video answer now
            app.state.study.stopping.set()
            super().handle_exit(sig, frame)

    # a stop waits at most 2 s for requests in flight: answers (a few ms each); a request waiting for a video is
    # answered at once (`StudyApp.stopping`)
    return StudyServer(
        uvicorn.Config(
            app,
            http=OneSendH11Protocol,  # a response's headers and body in one send
            log_level=log_level,
            access_log=False,
            lifespan="off",
            timeout_keep_alive=30,
            timeout_graceful_shutdown=2,
            # the client is the address that connects: uvicorn would take X-Forwarded-For from any local process;
            # the study reads it itself, from the proxies named with --trusted-proxy only (guard.TrustedProxies)
            proxy_headers=False,
        )
    )


class _Stopped(BaseException):
    """SIGTERM: stop serving, clean up, exit normally."""


def _on_sigterm(signum, frame) -> None:
    raise _Stopped


def limit_blas_threads(threads: int) -> bool:
    """Hold numpy's and scipy's BLAS to `threads` threads, as torch is: requests run in parallel threads, and a BLAS
    spinning threads of its own in each made choosing an active query 10-20x slower on 2 busy cores (p95 8 -> 160
    ms). Needs `threadpoolctl` (there with scikit-learn); False, and BLAS as it was, without it."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        return False
    threadpool_limits(limits=threads)
    return True


def check_db_path(db: str | Path) -> None:
    """What can be said about `--db` before the model is loaded: a directory or an unwritable place is refused."""
    path = Path(db)
    if path.is_dir():
        raise LangprefError(f"--db {path} is a directory; pass a file name such as {path / 'study.sqlite'}")
    if path.exists() and not path.is_file():
        raise LangprefError(f"--db {path} is not a regular file; pass a file name")
    parent = path.resolve().parent
    while not parent.exists():
        parent = parent.parent
    if not os.access(parent, os.W_OK) or (path.exists() and not os.access(path, os.R_OK | os.W_OK)):
        raise LangprefError(f"--db {path} cannot be written here (permissions); pass another --db")


def network_warning(host: str) -> str | None:
    """The warning printed when the server listens beyond this machine: plain HTTP, with a pointer to the proxy."""
    import ipaddress

    try:
        loopback = ipaddress.ip_address(host).is_loopback
    except ValueError:
        loopback = host == "localhost"
    if loopback:
        return None
    return (
        f"warning: --host {host} serves plain HTTP to the network: participants' tokens and answers travel "
        "unencrypted. On a shared network put a TLS reverse proxy in front and keep the server on 127.0.0.1 "
        "(docs/study.md; example configurations in langpref/study/deploy/)"
    )


def exit_now(code: int = 0) -> None:
    """End the process at once, skipping the interpreter's own teardown (torch's, MuJoCo's and EGL's libraries take
    a second or more, 3-5 s on a busy machine): for `langpref study serve` once `serve` has cleaned up after a
    SIGTERM. Every answer acknowledged was committed to the database (WAL: durable against a process ending)."""
    import logging

    logging.shutdown()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    os._exit(code)


def _announce(cfg: ServeConfig, state, sock: socket.socket, admin_token: str | None) -> None:
    """What the lab reads at start: the study, the hook, Study 1's generator (started here), the two addresses."""
    host, port = sock.getsockname()[:2]
    shown = f"[{host}]" if ":" in host else host
    url = f"http://{shown}:{port}"
    print(
        f"study of {state.engine.env}: {len(state.engine.study)} trajectories ({cfg.study.split}), database {cfg.db}",
        file=sys.stderr,
    )
    if state.hook is not None:
        print(f"on show: {state.hook.command} (timeout {cfg.on_show_timeout:g} s)", file=sys.stderr)
    if state.generated is not None:
        where = state.generated.store.root
        print(f"study 1: new trajectories made in the simulator, stored in {where}", file=sys.stderr)
        state.generated.start()
    print(f"participants: {url}/", flush=True)
    token = state.admin_token if admin_token is None else "(as given)"
    print(f"admin:        {url}/admin   token: {token}", flush=True)


def serve(cfg: ServeConfig) -> bool:
    """Run the study server until interrupted (SIGINT) or stopped (SIGTERM: its render workers and hook runs killed,
    answers in flight finished; well under a second). True when a SIGTERM stopped it (the command line then ends
    the process with `exit_now`)."""
    previous = (
        signal.signal(signal.SIGTERM, _on_sigterm) if threading.current_thread() is threading.main_thread() else None
    )
    state = sock = None
    stopped = False
    try:
        # everything that can be checked without the model first: a taken port or a bad --db fails in a second
        cfg.validate()
        admin_token = cfg.resolve_admin_token()
        check_db_path(cfg.db)
        sock = bind(cfg.host, cfg.port)
        warning = network_warning(cfg.host)
        if warning:
            print(warning, file=sys.stderr, flush=True)
        import torch

        torch.set_num_threads(max(1, cfg.torch_threads))
        limit_blas_threads(max(1, cfg.torch_threads))
        state = build_state(cfg, admin_token=admin_token)
        _announce(cfg, state, sock, admin_token)
        state.videos.start(prerender=cfg.prerender)
        _uvicorn_server(create_app(state)).run(sockets=[sock])
    except _Stopped:
        stopped = True
        print("stopped (SIGTERM)", file=sys.stderr, flush=True)
    finally:
        if state is not None:
            if state.generated is not None:
                state.generated.close()
            state.videos.close()
            if state.hook is not None:
                state.hook.close()
        if sock is not None:
            sock.close()
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)
    return stopped


class BackgroundServer:
    """A study server in a thread of this process (tests, benchmarks): `with BackgroundServer(state) as url: ...`."""

    def __init__(self, state: StudyApp, host: str = "127.0.0.1", port: int = 0):
        self.state = state
        self.sock = bind(host, port)
        self.port = self.sock.getsockname()[1]
        self.url = f"http://{host}:{self.port}"
        self.server = _uvicorn_server(create_app(state), log_level="error")
        self.thread = threading.Thread(target=self.server.run, kwargs={"sockets": [self.sock]}, daemon=True)

    def __enter__(self) -> str:
        import time

        self.thread.start()
        deadline = time.time() + 30
        while not self.server.started:
            if time.time() > deadline or not self.thread.is_alive():
                raise RuntimeError("the study server did not start")
            time.sleep(0.02)
        return self.url

    def __exit__(self, *exc) -> None:
        self.state.stopping.set()
        self.server.should_exit = True
        self.thread.join(timeout=30)
        self.sock.close()
