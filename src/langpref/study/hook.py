"""The live-robot hook of `langpref study serve --on-show CMD`: run CMD when a trajectory is about to be shown.

In the paper's studies participants watched the real robot replay each trajectory as well as its video. `--on-show`
is where a lab plugs in its replay (e.g. a ROS script): CMD runs once per trajectory of every step the server hands
out with videos (a comparison step runs it for A, then B), the first time that step is handed out by this server
process (a reload of the page does not replay, a restart of the server does).

CMD is one command line, split as a POSIX shell would split it (`shlex.split`) into a program and its arguments,
and run WITHOUT a shell; nothing a participant sends ever becomes command text. Shell syntax (pipes, `&&`) needs an
explicit shell: `--on-show "sh -c 'replay.sh && beep'"`. What to show comes in the environment (the server's own,
plus):

    LANGPREF_TRAJECTORY   the trajectory's index in the dataset LANGPREF_DATA
    LANGPREF_EPISODE      its recording's episode name (`Trajectory.source`); empty for a simulated dataset and
                          for a generated trajectory
    LANGPREF_PARTICIPANT  the participant's id (made by the server)
    LANGPREF_DATA         the dataset directory (absolute): the study's, or for a trajectory Study 1 made in the
                          simulator (`--improve-candidates generated`) the generated dataset (default DB.generated/)
    LANGPREF_KIND         the step's kind: language, comparison, satisfaction or rating
    LANGPREF_POSITION     the trajectory's place among the step's videos (0; 0 or 1 in a comparison)

A generated trajectory cannot be shown before the simulator has made it: its run waits aside (counted in the queue's
bound, holding no thread) and joins the queue when it is made, so it may run after runs of steps handed out later.

Hooks run one at a time, in the order steps were handed out (one robot replays one trajectory at a time), in one
background thread; a request only appends to a bounded queue, so a slow or failing hook never delays a step, an
answer or another participant. A run that exits non-zero (`failed`), cannot start (`error`), or outlives its
timeout (`timeout`: its process group is killed) is logged; a trajectory that finds no room is dropped (`skipped`).
The admin dashboard shows the counts and the last runs.

Room is shared out so that made-up participants cannot take the robot: only steps with videos run the hook, which
a participant reaches past the consent page and the first survey; one participant holds at most `per_participant`
runs waiting (a quarter of the queue); and when the queue is full, a run of a participant further into the study
(a later step) takes the place of the newest waiting run of the participant least far into it.

A run in flight when the server ends is killed with its whole process group: on a stop (Ctrl-C, SIGTERM) by the
server, and when the server is killed outright (`kill -9`, a crash) by a small watchdog process that holds a pipe
from the server and kills the groups of the runs in flight as soon as that pipe closes. No replay outlives the
server, so none goes on driving the robot unwatched, and its timeout always holds.
"""

from __future__ import annotations

import logging
import os
import shlex
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections import Counter, deque
from collections.abc import Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from langpref.dataset.storage import Dataset
    from langpref.study.generated import Generator

log = logging.getLogger("langpref.study")
STATUSES = ("ok", "failed", "timeout", "error", "skipped")
OUTPUT_TAIL = 500
"""Characters kept of a run's output (stdout and stderr together), from its end."""


def parse_command(command: str) -> list[str]:
    """The argv of a hook command line (shell-style quoting, no shell); ValueError if it is empty or unbalanced."""
    argv = shlex.split(command)
    if not argv:
        raise ValueError("the command is empty")
    return argv


@dataclass(frozen=True)
class ShowEvent:
    """One trajectory about to be shown to one participant."""

    participant: str
    seq: int
    kind: str
    position: int
    trajectory: int
    """Its index in the study's dataset, or for a generated trajectory in the generated dataset `data`."""
    data: str | None = None
    """The generated dataset (absolute) of a generated trajectory; None: the study's dataset."""
    shows: int = 1
    """How many trajectories the step shows (the admin page names the position, A, B, ..., of one of several)."""


@dataclass(frozen=True)
class HookRun:
    """The outcome of the hook for one event: a status of `STATUSES`, with the exit code and output when it ran."""

    event: ShowEvent
    episode: str | None
    status: str
    returncode: int | None
    started_at: float
    seconds: float
    output: str

    def to_json(self) -> dict[str, Any]:
        return {**asdict(self.event), **{k: v for k, v in asdict(self).items() if k != "event"}}


class ShowHook:
    """Runs the `--on-show` command for every trajectory shown, in a background thread with a bounded queue."""

    def __init__(
        self,
        command: str,
        dataset: Dataset,
        timeout_s: float = 60.0,
        queue_size: int = 64,
        keep: int = 20,
        per_participant: int | None = None,
    ):
        self.command = command
        self.argv = parse_command(command)
        self.dataset = dataset
        self.timeout_s = timeout_s
        self.queue_size = queue_size
        self.per_participant = per_participant or max(2, queue_size // 4)
        """Runs one participant may have waiting at once (2: a comparison step's)."""
        self._queue: deque[ShowEvent] = deque()
        self._recent: deque[HookRun] = deque(maxlen=keep)
        self._counts: Counter[str] = Counter()
        self._handed_out: set[tuple[str, int]] = set()
        self._episodes: dict[int, str | None] = {}
        self.generated: Generator | None = None
        self._waiting: dict[int, list[ShowEvent]] = {}
        """Generated trajectory id -> the runs waiting for the simulator to make it."""
        self._running: ShowEvent | None = None
        self._proc: subprocess.Popen[bytes] | None = None
        self._stopped = False
        self._cond = threading.Condition()
        self._watchdog = Watchdog()
        self._thread = threading.Thread(target=self._run, name="on-show-hook", daemon=True)
        self._thread.start()

    def attach(self, generated: Generator) -> None:
        """Run for Study 1's generated trajectories too, each once the simulator has made it."""
        self.generated = generated
        generated.on_made.append(self._made)

    # ---- request side (never blocks, never raises for a hook's sake) ----

    def show(self, participant: str, seq: int, kind: str, trajectories: Sequence[int]) -> None:
        """Queue the hook for each trajectory of a step handed out to a participant (once per step); a generated
        trajectory not made yet waits aside until it is."""
        with self._cond:
            if not trajectories or (participant, seq) in self._handed_out or self._stopped:
                return
            self._handed_out.add((participant, seq))
            for position, index in enumerate(trajectories):
                event = ShowEvent(participant, seq, kind, position, int(index), shows=len(trajectories))
                if sum(e.participant == participant for e in self._waiting_events()) >= self.per_participant:
                    self._skip(event, f"this participant already had {self.per_participant} runs waiting")
                elif len(self._queue) + self._waiting_runs() >= self.queue_size and not self._make_room(seq):
                    self._skip(event, f"{self.queue_size} runs were already waiting")
                elif self.generated is not None and self.generated.owns(index):
                    # checked under our lock: `_made` takes it too, so no run is left waiting for a made trajectory
                    row = self.generated.store_index(index)
                    if row is None:
                        self._waiting.setdefault(int(index), []).append(event)
                    else:
                        self._queue.append(self._in_store(event, row))
                else:
                    self._queue.append(event)
            self._cond.notify_all()

    def _skip(self, event: ShowEvent, why: str) -> None:
        self._record(HookRun(event, None, "skipped", None, time.time(), 0.0, why))

    def _waiting_events(self) -> list[ShowEvent]:
        """Every run waiting, for its turn or for its trajectory to be made (call with `_cond` held)."""
        return [*self._queue, *(e for events in self._waiting.values() for e in events)]

    def _make_room(self, seq: int) -> bool:
        """Drop the newest waiting run of the participant least far into the study (the lowest step seq), if that is
        before step `seq`; whether a run was dropped (call with `_cond` held)."""
        waiting = self._waiting_events()
        if not waiting:
            return False
        lowest = min(e.seq for e in waiting)
        if lowest >= seq:
            return False
        victim = [e for e in waiting if e.seq == lowest][-1]
        if victim in self._queue:
            self._queue.remove(victim)
        else:
            for events in self._waiting.values():
                if victim in events:
                    events.remove(victim)
        self._waiting = {k: v for k, v in self._waiting.items() if v}
        self._skip(victim, "made room for a participant further into the study")
        return True

    def _waiting_runs(self) -> int:
        """Runs waiting for a generated trajectory to be made (call with `_cond` held); they count in the bound."""
        return sum(map(len, self._waiting.values()))

    def _in_store(self, event: ShowEvent, row: int) -> ShowEvent:
        """The run of a generated trajectory, made: its index in the generated dataset, and that dataset."""
        return replace(event, trajectory=row, data=str(Path(self.generated.store.root).resolve()))

    def _made(self, index: int) -> None:
        """The simulator has made generated trajectory `index`: queue the runs waiting for it (generator thread)."""
        row = self.generated.store_index(index)
        with self._cond:
            events = self._waiting.pop(int(index), [])
            if row is None or self._stopped:
                return
            self._queue.extend(self._in_store(e, row) for e in events)
            self._cond.notify_all()

    def status(self) -> dict[str, Any]:
        """For the admin dashboard: the command, counts per status, what waits and runs, the last runs (newest
        first)."""
        with self._cond:
            return {
                "command": self.command,
                "timeout_s": self.timeout_s,
                "queued": len(self._queue),
                "waiting_for_generation": self._waiting_runs(),
                "running": asdict(self._running) if self._running else None,
                "counts": {s: self._counts[s] for s in STATUSES},
                "recent": [r.to_json() for r in reversed(self._recent)],
            }

    def wait(self, timeout: float = 60.0) -> bool:
        """Wait until nothing waits (for its turn or for a generated trajectory) or runs (tests, shutdown)."""
        with self._cond:
            return self._cond.wait_for(lambda: not self._queue and not self._waiting and self._running is None, timeout)

    def close(self) -> None:
        """Stop: drop what waits, kill a running hook's process group, end the thread."""
        with self._cond:
            self._stopped = True
            self._queue.clear()
            self._waiting.clear()
            if self._proc is not None:
                _kill_group(self._proc)
            self._cond.notify_all()
        self._thread.join(timeout=10)
        self._watchdog.close()

    # ---- the background thread ----

    def _record(self, run: HookRun) -> None:
        """Keep a finished run for the dashboard and log it unless it went well (call with `_cond` held)."""
        self._recent.append(run)
        self._counts[run.status] += 1
        if run.status != "ok":
            e = run.event
            log.warning(
                "--on-show hook %s for trajectory %d (participant %s, %s step): exit code %s, %.1f s; %s",
                run.status,
                e.trajectory,
                e.participant[:8],
                e.kind,
                run.returncode,
                run.seconds,
                run.output[-200:].strip() or "no output",
            )

    def _run(self) -> None:
        while True:
            with self._cond:
                self._cond.wait_for(lambda: self._queue or self._stopped)
                if self._stopped:
                    return
                event = self._running = self._queue.popleft()
            try:
                run = self._execute(event)
            except Exception as exc:  # noqa: BLE001 (a broken run is reported; the thread serves the next one)
                run = HookRun(event, None, "error", None, time.time(), 0.0, f"{type(exc).__name__}: {exc}")
            with self._cond:
                self._running = None
                self._record(run)
                self._cond.notify_all()

    def _episode(self, index: int) -> str | None:
        if index not in self._episodes:
            self._episodes[index] = self.dataset.load(index).source
        return self._episodes[index]

    def _execute(self, event: ShowEvent) -> HookRun:
        """Run the command for one event, its output into a temporary file (a pipe could block on a grandchild)."""
        episode = None if event.data else self._episode(event.trajectory)  # a generated one has no recording
        env = {
            **os.environ,
            "LANGPREF_TRAJECTORY": str(event.trajectory),
            "LANGPREF_EPISODE": episode or "",
            "LANGPREF_PARTICIPANT": event.participant,
            "LANGPREF_DATA": event.data or str(self.dataset.root.resolve()),
            "LANGPREF_KIND": event.kind,
            "LANGPREF_POSITION": str(event.position),
        }
        started, t0 = time.time(), time.monotonic()
        with tempfile.TemporaryFile() as out:
            try:
                proc = subprocess.Popen(
                    self.argv,
                    env=env,
                    stdin=subprocess.DEVNULL,
                    stdout=out,
                    stderr=subprocess.STDOUT,
                    start_new_session=True,
                )
            except OSError as exc:
                return HookRun(
                    event,
                    episode,
                    "error",
                    None,
                    started,
                    time.monotonic() - t0,
                    f"cannot start {self.argv[0]}: {exc.strerror or exc}",
                )
            self._watchdog.watch(proc.pid)  # its own session: the group id is its pid
            with self._cond:
                self._proc = proc
                if self._stopped:
                    _kill_group(proc)
            try:
                proc.wait(timeout=self.timeout_s)
                status = "ok" if proc.returncode == 0 else "failed"
            except subprocess.TimeoutExpired:
                _kill_group(proc)
                proc.wait()
                status = "timeout"
            finally:
                with self._cond:
                    self._proc = None
                self._watchdog.forget(proc.pid)
            size = out.seek(0, os.SEEK_END)
            out.seek(max(0, size - 4 * OUTPUT_TAIL))  # at most 4 bytes per character
            output = out.read().decode("utf-8", "replace")[-OUTPUT_TAIL:]
        if status == "timeout":
            output = f"killed after {self.timeout_s:g} s\n{output}"
        return HookRun(event, episode, status, proc.returncode, started, time.monotonic() - t0, output)


def _kill_group(proc: subprocess.Popen[bytes]) -> None:
    """Kill the hook and everything it started (its own session, see `start_new_session`), unless it has ended."""
    if proc.returncode is not None:
        return
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass


WATCHDOG = """
import os, signal, sys
groups = set()
for line in sys.stdin:
    (groups.add if line[0] == "+" else groups.discard)(int(line[1:]))
for group in groups:
    try:
        os.killpg(group, signal.SIGKILL)
    except OSError:
        pass
"""
"""The watchdog's program: it reads `+GROUP` / `-GROUP` lines until the server's end of the pipe closes (the server
has ended, however), then kills the process groups still listed."""


class Watchdog:
    """A process that kills the hook runs in flight when the server ends, even by `kill -9`: it is told each run's
    process group over a pipe, and the pipe closes when the server's process does. Without it (it could not start)
    only a stop the server sees kills them."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        try:
            self._proc: subprocess.Popen[bytes] | None = subprocess.Popen(
                [sys.executable, "-I", "-S", "-c", WATCHDOG],
                stdin=subprocess.PIPE,
                stdout=subprocess.DEVNULL,
                stderr=subprocess.DEVNULL,
                start_new_session=True,  # a Ctrl-C of the server's terminal leaves it to do its job
            )
        except OSError as exc:
            log.warning("--on-show: no watchdog (%s); a hook run may outlive a server that is killed", exc)
            self._proc = None

    def _send(self, line: str) -> None:
        with self._lock:
            if self._proc is None or self._proc.stdin is None:
                return
            try:
                self._proc.stdin.write(line.encode())
                self._proc.stdin.flush()
            except (BrokenPipeError, ValueError):
                pass

    def watch(self, group: int) -> None:
        self._send(f"+{group}\n")

    def forget(self, group: int) -> None:
        self._send(f"-{group}\n")

    def close(self) -> None:
        """End the watchdog (every run has ended or was killed): it kills what is still listed and exits."""
        with self._lock:
            proc, self._proc = self._proc, None
        if proc is not None:
            if proc.stdin is not None:
                proc.stdin.close()
            try:
                proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
