"""Configuration of a study: the protocol (saved in the database, fixed for its lifetime) and how to serve it."""

from __future__ import annotations

import shutil
from dataclasses import asdict, dataclass, field, fields
from typing import Any

from langpref.errors import LangprefError
from langpref.study.guard import TrustedProxies
from langpref.study.hook import parse_command

METHODS = ("language", "comparison")
"""The paper's two Study-2 methods (`langpref.feedback.kind.PAPER_KINDS`, spelled out here so that the CLI's help
imports no numpy): the default `StudyConfig.kinds`, and the two the analyses compare."""
VIDEO_FORMATS = ("webm", "mp4")
IMPROVE_CANDIDATES = ("split", "generated")
ADMIN_TOKEN_ENV = "LANGPREF_STUDY_ADMIN_TOKEN"


@dataclass
class StudyConfig:
    """The protocol of the paper's two studies (Sec. 5.2); the defaults are the paper's."""

    split: str = "test"
    """Dataset split whose trajectories the study shows and searches (`train`, `val`, `test` or `all`)."""
    improve_max_iterations: int = 10
    """Study 1: most rounds of feedback before the improvement survey."""
    improve_candidates: str = "split"
    """Study 1: where an improvement step looks: `split` (the study set, the paper's) or `generated` (a new trajectory
    made in the simulator for each feedback, `langpref.propose`; simulated tasks only; the page shows progress while
    it is made)."""
    improve_rollouts: int = 6
    """Study 1 with generated candidates: real rollouts per improvement step, the best of which is shown."""
    improve_search_generations: int = 30
    """Study 1 with generated candidates: CMA-ES generations on the surrogate per improvement step."""
    kinds: tuple[str, ...] = METHODS
    """Study 2's methods: the feedback kinds it asks, each in turn (`langpref.study.kinds`), in the order the first
    participant meets them (each next arrival starts one later). Any registered kind with a study page runs, a
    plugin's too (entry-point group `langpref.feedback`); the paper's: language,comparison."""
    pref_queries: int = 20
    """Study 2: queries per method."""
    rating_every: int = 5
    """Study 2: after every this many queries, the best trajectory under the reward learned so far is rated 1-5."""
    num_negatives: int = 20
    """k, implicit-negative utterances per language answer in reward learning (Eq. 9)."""
    seed: int = 0
    """Seed of the study: with the participant's own seed it fixes every trajectory drawn for them."""
    query_selection: str = "random"
    """Study 2: how each query is chosen from the study set, from the participant's answers so far
    (`langpref.reward.selection`): `random` (the paper's), `infogain` (both methods), or one per method as
    `language=lal-infogain,comparison=volume-removal` (language: random, infogain, lal-infogain; comparisons: random,
    infogain, volume-removal; a method left out is random)."""
    query_candidates: int = 60
    """Study 2, active query selection: score at most this many trajectories of the study set per query (drawn for
    each query; comparisons score every pair of them), which bounds the time an answer waits for the next query."""
    learner: str = "paper"
    """Study 2's reward learner, for both methods: `paper` (Eq. 5-9's Bradley-Terry pairs, the paper's) or
    `answer-model` (a belief over the reward that reads a sentence given the trajectory it was said about, with
    comparisons in the same belief; `langpref.reward.answer_model`; random or infogain queries)."""
    confirm_margin: float | None = None
    """Study 2, ask when unsure: when the model's reading of a typed language answer is uncertain (P of its top
    meaning minus P of the second below this margin), the participant confirms the meaning with one click among its
    top 3 readings or "none of these" (then the answer is stored and not learned from). None: never, the paper's
    protocol; 1: always."""

    def validate(self) -> None:
        if self.split not in ("train", "val", "test", "all"):
            raise LangprefError(f"--split must be train, val, test or all, got {self.split!r}")
        if self.improve_candidates not in IMPROVE_CANDIDATES:
            raise LangprefError(
                f"--improve-candidates must be {' or '.join(IMPROVE_CANDIDATES)}, got {self.improve_candidates!r}"
            )
        names = ("improve_max_iterations", "pref_queries", "rating_every", "num_negatives", "improve_rollouts")
        for name in (*names, "improve_search_generations"):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 1:
                raise LangprefError(f"{name} must be an integer >= 1, got {value!r}")
        if not isinstance(self.query_candidates, int) or self.query_candidates < 2:
            raise LangprefError(f"--query-candidates must be an integer >= 2, got {self.query_candidates!r}")
        margin = self.confirm_margin
        if margin is not None and (
            isinstance(margin, bool) or not isinstance(margin, (int, float)) or not 0 <= margin <= 1
        ):
            raise LangprefError(f"--confirm-margin must be a number from 0 to 1 (or unset: never ask), got {margin!r}")
        from langpref.feedback.kind import kind_names, paper_first
        from langpref.reward.learners import get_learner, learner_names

        known = learner_names()

        if self.learner not in known:
            raise LangprefError(f"--learner must be {' or '.join(known)}, got {self.learner!r}")
        from langpref.study.kinds import check_kinds

        self.kinds = check_kinds(self.kinds)
        selections = self.selections()
        learner = get_learner(self.learner)
        unread = sorted(k for k in self.kinds if not learner.reads(k))
        if unread:
            read = " and ".join(paper_first([k for k in kind_names() if learner.reads(k)]))
            raise LangprefError(f"--learner {self.learner} reads {read} only, not {', '.join(unread)}")
        other = sorted({s for s in selections.values() if learner.selections and s not in learner.selections})
        if other:
            asks = learner.selections
            raise LangprefError(
                f"--learner {self.learner} asks with {' or '.join(asks)} queries, not {', '.join(other)}; "
                f"pass --query-selection {asks[-1]}" + (f" (or {' or '.join(asks[:-1])})" if len(asks) > 1 else "")
            )

    def selections(self) -> dict[str, str]:
        """The query selection strategy of each Study-2 method, checked (one line naming the choices otherwise)."""
        from langpref.reward.selection import STRATEGIES, check_strategy

        text = str(self.query_selection).strip()
        if "=" not in text:
            out = dict.fromkeys(self.kinds, text)
        else:
            out = dict.fromkeys(self.kinds, "random")
            for item in filter(None, (x.strip() for x in text.split(","))):
                method, _, strategy = (x.strip() for x in item.partition("="))
                if method not in self.kinds:
                    raise LangprefError(
                        f"--query-selection {text}: {method!r} is no Study-2 method; name "
                        f"{' or '.join(self.kinds)}, e.g. language=infogain,comparison=volume-removal"
                    )
                out[method] = strategy
        for method, strategy in out.items():
            try:
                check_strategy(strategy, method)
            except LangprefError as exc:
                per_method = "=" not in text and strategy in STRATEGIES
                each = ",".join(f"{k}=NAME" for k in self.kinds)
                hint = f" (or give one per method: {each})" if per_method else ""
                raise LangprefError(f"--query-selection {text}: {exc}{hint}") from None
        return out

    def rating_points(self) -> list[int]:
        """Query counts after which the best trajectory is rated: every `rating_every`, and the last query."""
        points = list(range(self.rating_every, self.pref_queries + 1, self.rating_every))
        if not points or points[-1] != self.pref_queries:
            points.append(self.pref_queries)
        return points

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, raw: dict[str, Any]) -> StudyConfig:
        known = {f.name for f in fields(cls)}
        out = cls(**{k: v for k, v in raw.items() if k in known})
        out.kinds = tuple(out.kinds)  # a list in the database's JSON
        return out


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
    what to show comes in LANGPREF_* environment variables (see `langpref.study.hook`)."""
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
class ExportConfig:
    """`langpref study export`: tables, analyses and figures of a study."""

    db: str = ""
    """The study's SQLite database (`langpref study serve --db`)."""
    out: str = ""
    """Output directory (created if missing; an existing file is refused)."""
    exclude: tuple[str, ...] = ()
    """Participants to leave out of the analyses (`--exclude 3,7`: arrival numbers, or ids as the dashboard shows them),
    besides those marked excluded on the dashboard; the tables keep every row."""
    bank_additions: str | None = None
    """Also write the phrasings participants confirmed the meaning of (`--confirm-margin`) to this JSON file for the
    lab to review: each text under each meaning chosen, with its count, participants, margins and flags (the same
    text confirmed otherwise, a text naming no change, the bank's own reading). No command reads it as a bank until
    `langpref bank review FILE --out BANK` writes the accepted ones. An existing file is refused without `--force`,
    and the study database always."""
    model: str | None = None
    """The study's model folder, where it is no longer where the study ran (the saved rewards refer to it)."""


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
