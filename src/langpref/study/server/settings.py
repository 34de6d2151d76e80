"""The options of the study's server commands: `langpref study serve` (`ServeConfig`, its videos `VideoConfig`)
and `langpref study simulate` (`SimulateConfig`). Light on purpose: the CLI reads them to build its options, with no
web framework or numpy imported. The protocol they serve is `langpref.study.protocol.config.StudyConfig`."""

from __future__ import annotations

import shutil
from dataclasses import dataclass, field

from langpref.errors import LangprefError
from langpref.study.protocol.config import StudyConfig
from langpref.study.server.guard import TrustedProxies
from langpref.study.server.hook import parse_command

VIDEO_FORMATS = ("webm", "mp4")
ADMIN_TOKEN_ENV = "LANGPREF_STUDY_ADMIN_TOKEN"


@dataclass
class VideoConfig:
    """How study videos are served: their format, and for a simulated dataset how they are rendered (one frame per
    `stride` stored steps, played at `fps`); a recorded dataset's videos keep their own size and frame rate."""

    format: str = "webm"
    """`webm` (VP9, plays in Debian's Chromium and every current browser) or `mp4` (H.264); a recorded video in
    another format is transcoded once."""
    width: int = 320
    """Width of rendered videos in pixels (recorded videos keep their own size and frame rate)."""
    height: int = 240
    """Height of rendered videos in pixels."""
    fps: int = 30
    """Frame rate of rendered videos."""
    stride: int = 2
    """Rendered videos show one frame per this many stored steps."""

    def validate(self) -> None:
        if self.format not in VIDEO_FORMATS:
            raise LangprefError(f"video format must be one of {', '.join(VIDEO_FORMATS)}, got {self.format!r}")
        if not (16 <= self.width <= 1920 and 16 <= self.height <= 1080):
            raise LangprefError(f"video size {self.width}x{self.height} is out of range (16..1920 x 16..1080)")
        if self.fps < 1 or self.stride < 1:
            raise LangprefError("video fps and stride must be >= 1")


@dataclass
class ServeConfig:
    """`langpref study serve`: which model and data, where state lives, and where to listen."""

    model: str = ""
    """Checkpoint directory (`langpref train`)."""
    data: str = ""
    """Dataset directory (`langpref generate`, or `langpref import` for a recording with its videos)."""
    db: str = "study.sqlite"
    """SQLite database; created on first start, continued on later ones."""
    videos: str | None = None
    """Video cache folder; default `DB.videos/` beside the database."""
    generated: str | None = None
    """Where Study 1 stores the trajectories it makes with `--improve-candidates generated` (a dataset); default
    `DB.generated/` beside the database."""
    host: str = "127.0.0.1"
    """Address to listen on: 127.0.0.1 is this machine only; 0.0.0.0 opens the study to the network."""
    port: int = 8000
    """Port to listen on; 0 picks a free one."""
    admin_token: str | None = None
    """Bearer token of the admin pages and export. A command line shows in `ps`: prefer the environment variable
    LANGPREF_STUDY_ADMIN_TOKEN or `admin_token_file`. A random one is made and printed when none is given."""
    admin_token_file: str | None = None
    """File holding the admin token (its first line; keep it readable only by you): `--admin-token-file`."""
    prerender: bool = True
    """Render every study video in the background at start (with progress), so that no participant waits."""
    torch_threads: int = 1
    """Torch (and numpy's BLAS) threads per request; requests of different participants run in parallel threads."""
    on_show: str | None = None
    """Command line run (without a shell) before each trajectory is shown, e.g. to replay it on the real robot;
    what to show comes in LANGPREF_* environment variables (see `langpref.study.server.hook`)."""
    allowed_origins: tuple[str, ...] = ()
    """Origins (`https://study.lab.example`) whose pages may send answers besides the server's own (the Host it was
    reached at): needed only behind a proxy that rewrites the Host header. Cross-site POSTs are refused."""
    allowed_hosts: tuple[str, ...] = ()
    """Host names the study may be reached under besides localhost, 127.0.0.1, ::1, any address (`192.168.1.5`),
    the `host` it listens on and the hosts of `allowed_origins`: e.g. the machine's name when participants open
    `http://labpc.local:8000`. A request for any other name is refused (a DNS-rebinding page's)."""
    on_show_timeout: float = 60.0
    """Seconds an `on_show` run may take before it is killed and reported as timed out."""
    trusted_proxies: tuple[str, ...] = ()
    """Reverse proxies (addresses or networks: 127.0.0.1, 10.0.0.0/24) whose X-Forwarded-For header names the
    client, whom wrong resume codes are counted against. None by default: the address that connects is the client,
    whatever it sends. Behind the shipped nginx site: `--trusted-proxy 127.0.0.1`."""
    signups_per_client: int = 20
    """New participants one client (an address, as for wrong resume codes; IPv6 by its /64) may start in 10
    minutes, then 429 for that client until the oldest is 10 minutes old; 0: no limit. A lab's one computer
    starts far fewer; junk sign-ups from one client stay a few among the turns of the robot and the simulator."""
    study: StudyConfig = field(default_factory=StudyConfig)
    video: VideoConfig = field(default_factory=VideoConfig)

    def validate(self) -> None:
        if not self.model:
            raise LangprefError("no model given: pass --model MODEL_DIR (`langpref train`)")
        if not self.data:
            raise LangprefError("no dataset given: pass --data DIR (`langpref generate`)")
        if not 0 <= self.port <= 65535:
            raise LangprefError(f"--port must be 0..65535, got {self.port}")
        if self.admin_token is not None and self.admin_token_file is not None:
            raise LangprefError("pass --admin-token or --admin-token-file, not both")
        self.resolve_admin_token()
        if self.on_show is not None:
            try:
                program = parse_command(self.on_show)[0]
            except ValueError as exc:
                raise LangprefError(f"--on-show {self.on_show!r} is not a command line ({exc})") from None
            if shutil.which(program) is None:
                raise LangprefError(
                    f"--on-show: program {program!r} not found or not executable; give its path or put it on PATH"
                )
        self.allowed_hosts = tuple(self.allowed_hosts or ())
        for name in self.allowed_hosts:
            if not name.strip() or "/" in name or any(c.isspace() for c in name):
                raise LangprefError(f"--allowed-hosts {name!r}: give a host name such as labpc.local, not a URL")
        proxies = []
        for value in self.trusted_proxies or ():
            try:
                proxies.append(TrustedProxies.check(value))
            except ValueError:
                raise LangprefError(
                    f"--trusted-proxy {value!r}: give the proxy's address or network, e.g. 127.0.0.1 or 10.0.0.0/24"
                ) from None
        self.trusted_proxies = tuple(proxies)
        if self.signups_per_client < 0:
            raise LangprefError(f"--signups-per-client must be >= 0 (0: no limit), got {self.signups_per_client}")
        if not self.on_show_timeout > 0:
            raise LangprefError(f"--on-show-timeout must be > 0 seconds, got {self.on_show_timeout}")
        self.study.validate()
        self.video.validate()

    def resolve_admin_token(self) -> str | None:
        """The admin token given: `admin_token`, else the first line of `admin_token_file`, else the environment
        variable LANGPREF_STUDY_ADMIN_TOKEN; None when none is given (the server then makes a random one)."""
        import os
        from pathlib import Path

        token, where = self.admin_token, "--admin-token"
        if token is None and self.admin_token_file is not None:
            path, where = Path(self.admin_token_file), f"--admin-token-file {self.admin_token_file}"
            try:
                token = (path.read_text().splitlines() or [""])[0].strip()
            except (OSError, UnicodeDecodeError) as exc:
                raise LangprefError(
                    f"cannot read the admin token from {path} ({exc.__class__.__name__}); pass a readable text file"
                ) from None
        if token is None and os.environ.get(ADMIN_TOKEN_ENV):
            token, where = os.environ[ADMIN_TOKEN_ENV].strip(), ADMIN_TOKEN_ENV
        if token is not None and len(token) < 16:
            raise LangprefError(
                f"the admin token ({where}) must be at least 16 characters (or give none for a random one)"
            )
        return token


@dataclass
class SimulateConfig:
    """`langpref study simulate`: simulated participants (synthetic humans) against a running study server."""

    url: str = ""
    """The server's address as `study serve` prints it, e.g. http://127.0.0.1:8000."""
    db: str | None = None
    """The server's SQLite database on this machine (only read): the dataset and split default to the study's, and
    with `--improve-candidates generated` the participants learn from it what the server generated. Without --db and
    --data they answer at random."""
    data: str | None = None
    """The study's dataset directory (default: the one --db was created with): the participants answer as synthetic
    humans over its features."""
    split: str | None = None
    """The study split (default: the --db study's, else test)."""
    generated: str | None = None
    """The server's dataset of generated trajectories (`study serve --generated`); default `DB.generated/` beside
    --db, as the server's."""
