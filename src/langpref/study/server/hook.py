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

Hooks run one at a time (one robot replays one trajectory at a time), in turns (below), in one background thread;
a request only appends to a bounded queue, so a slow or failing hook never delays a step, an answer or another
participant. A run that exits non-zero (`failed`), cannot start (`error`), or outlives its
timeout (`timeout`: its process group is killed) is logged; a trajectory that finds no room is dropped (`skipped`).
The admin dashboard shows the counts and the last runs.

Room and turns are shared out so that made-up participants cannot take the robot (sign-ups alone cost a client
nothing but a request each; `study serve` also limits them per client):

- Work is earned by answering. A step's runs are a newcomer's while the participant has answered no step with
  videos (`ShowEvent.earned`, counted by the server from the stored answers). Newcomers' runs share
  `newcomer_slots` places (a quarter of the queue): a newcomer's run takes the place of the oldest newcomer's step
  (that participant has not answered since; a made-up sign-up never does), so sign-ups can never fill the queue.
- Turns are fair. The robot serves one participant's step after another, round robin: the next run is of the
  participant whose last turn is longest ago (never: first; then whose run waits longest), their oldest step first;
  the newcomers together take one turn, the newest step first (the participant most likely still watching). A
  step's runs are not split: B is replayed right after A.
- One participant holds at most `per_participant` runs waiting (a quarter of the queue); when the queue is full, a
  run takes the place of the oldest newcomer's step, else of the newest run of the participant holding the most
  runs (when they hold more than one more than this participant), else it is skipped.

So a real participant's first replay starts after the run in flight and at most one turn of each participant
waiting, and each later one after at most one turn of each other participant, however many made-up participants
signed up before.

A run in flight when the server ends is killed with its whole process group: on a stop (Ctrl-C, SIGTERM) by the
server, and when the server is killed outright (`kill -9`, a crash) by a small watchdog process that holds a pipe
from the server and kills the groups of the runs in flight as soon as that pipe closes. No replay outlives the
server, so none goes on driving the robot unwatched, and its timeout always holds.
"""

from __future__ import annotations

import logging
import os
import shlex
import subprocess
import tempfile
import threading
import time
from collections import Counter, deque
from collections.abc import Sequence
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from langpref.study.server.watchdog import Watchdog, kill_group

if TYPE_CHECKING:
    from langpref.dataset.storage import Dataset
    from langpref.study.session.generated import Generator

log = logging.getLogger("langpref.study")
STATUSES = ("ok", "failed", "timeout", "error", "skipped")
OUTPUT_TAIL = 500
"""Characters kept of a run's output (stdout and stderr together), from its end."""
NEWCOMERS = ""
"""The lane whose turns the steps of participants who have answered no step with videos share."""


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
    earned: int = 0
    """Steps with videos the participant had answered when this step was handed out (0: a newcomer's step)."""
    order: int = 0
    """The step's place among the steps handed out (this server process's count): which waited longest."""


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
        newcomer_slots: int | None = None,
    ):
        self.command = command
        self.argv = parse_command(command)
        self.dataset = dataset
        self.timeout_s = timeout_s
        self.queue_size = queue_size
        self.per_participant = per_participant or max(2, queue_size // 4)
        """Runs one participant may have waiting at once (2: a comparison step's)."""
        self.newcomer_slots = newcomer_slots or max(2, queue_size // 4)
        """Runs that participants who have answered no step with videos may have waiting, all together."""
        self._queue: deque[ShowEvent] = deque()
        self._steps: Counter[str] = Counter()
        """Steps with videos handed out per participant (what they have earned, when the server does not say)."""
        self._answered: set[str] = set()
        """Participants who have answered a step with videos: none of their steps is a newcomer's any more."""
        self._turns = 0
        self._last_turn: dict[str, int] = {}
        """Lane (a participant, or `NEWCOMERS`) -> the number of the turn it last had."""
        self._step: tuple[str, int] | None = None
        """(participant, seq) of the step whose run started last: its other runs come next."""
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

    def show(
        self, participant: str, seq: int, kind: str, trajectories: Sequence[int], earned: int | None = None
    ) -> None:
        """Queue the hook for each trajectory of a step handed out to a participant (once per step), who had answered
        `earned` steps with videos before it (None: as many as this hook was told of); a generated trajectory not
        made yet waits aside until it is."""
        with self._cond:
            if not trajectories or (participant, seq) in self._handed_out or self._stopped:
                return
            self._handed_out.add((participant, seq))
            earned = self._steps[participant] if earned is None else int(earned)
            self._steps[participant] += 1
            if earned:
                self._answered.add(participant)
            order = len(self._handed_out)
            for position, index in enumerate(trajectories):
                event = ShowEvent(participant, seq, kind, position, int(index), None, len(trajectories), earned, order)
                refused = self._admit(event)
                if refused:
                    self._skip(event, refused)
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

    def handed_out(self, participant: str, seq: int) -> bool:
        """Whether the hook was told of this step already (a reload of the page: nothing to count or run)."""
        with self._cond:
            return (participant, seq) in self._handed_out

    def _skip(self, event: ShowEvent, why: str) -> None:
        self._record(HookRun(event, None, "skipped", None, time.time(), 0.0, why))

    def _waiting_events(self) -> list[ShowEvent]:
        """Every run waiting, for its turn or for its trajectory to be made (call with `_cond` held)."""
        return [*self._queue, *(e for events in self._waiting.values() for e in events)]

    def _admit(self, event: ShowEvent) -> str | None:
        """Make room for `event` as the rules of the module say; why it is skipped, or None when it may wait (call
        with `_cond` held)."""
        waiting = self._waiting_events()
        if sum(e.participant == event.participant for e in waiting) >= self.per_participant:
            return f"this participant already had {self.per_participant} runs waiting"
        if self._newcomer(event) and sum(map(self._newcomer, waiting)) >= self.newcomer_slots:
            if not self._drop_newcomer(event):
                return f"{self.newcomer_slots} runs of participants who had answered no step were already waiting"
        if len(self._waiting_events()) >= self.queue_size and not self._make_room(event):
            return f"{self.queue_size} runs were already waiting"
        return None

    def _drop_newcomer(self, event: ShowEvent) -> bool:
        """Drop the oldest step of another participant who has answered no step with videos (they have not
        answered it since it was handed out); whether one was dropped (call with `_cond` held)."""
        others = [e for e in self._waiting_events() if self._newcomer(e) and e.participant != event.participant]
        if not others:
            return False
        oldest = min(e.order for e in others)
        for victim in [e for e in others if e.order == oldest]:
            self._remove(victim, "a newer participant's step took its place (this one had answered no step since)")
        return True

    def _make_room(self, event: ShowEvent) -> bool:
        """The queue is full: drop the oldest newcomer's step, else the newest run of the participant holding the
        most runs when they hold more than one more than `event`'s participant; whether a run was dropped (call
        with `_cond` held)."""
        if self._drop_newcomer(event):
            return True
        held = Counter(e.participant for e in self._waiting_events())
        top, most = max(held.items(), key=lambda item: item[1], default=(None, 0))
        if most <= held[event.participant] + 1:
            return False
        victim = max((e for e in self._waiting_events() if e.participant == top), key=lambda e: (e.order, e.position))
        self._remove(victim, "made room for a participant holding fewer runs")
        return True

    def _newcomer(self, event: ShowEvent) -> bool:
        """Whether `event` is the step of a participant who has answered no step with videos (as yet)."""
        return not event.earned and event.participant not in self._answered

    def _lane(self, event: ShowEvent) -> str:
        """Whose turn `event` takes: its participant's, or a newcomer's, the newcomers' (`NEWCOMERS`)."""
        return NEWCOMERS if self._newcomer(event) else event.participant

    def _remove(self, victim: ShowEvent, why: str) -> None:
        """Take a waiting run out of the queue (or of those waiting for the simulator), reported as skipped."""
        if victim in self._queue:
            self._queue.remove(victim)
        else:
            for events in self._waiting.values():
                if victim in events:
                    events.remove(victim)
            self._waiting = {k: v for k, v in self._waiting.items() if v}
        self._skip(victim, why)

    def _next(self) -> ShowEvent:
        """Take the next run of the queue (not empty; call with `_cond` held): the rest of the step in flight, else
        the turn of the lane (a participant, or the newcomers together) whose last turn is longest ago (never
        first; then the one whose run waits longest): a participant's oldest step, the newcomers' newest."""
        rest = [e for e in self._queue if (e.participant, e.seq) == self._step]
        if rest:
            event = min(rest, key=lambda e: e.position)
        else:
            lanes: dict[str, list[ShowEvent]] = {}
            for e in self._queue:
                lanes.setdefault(self._lane(e), []).append(e)
            lane = min(lanes, key=lambda k: (self._last_turn.get(k, -1), min(e.order for e in lanes[k])))
            newest = lane == NEWCOMERS
            event = min(lanes[lane], key=lambda e: (-e.order if newest else e.order, e.position))
            self._turns += 1
            self._last_turn[lane] = self._turns
        self._queue.remove(event)
        self._step = (event.participant, event.seq)
        return event

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
                kill_group(self._proc)
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
                event = self._running = self._next()
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
                    kill_group(proc)
            try:
                proc.wait(timeout=self.timeout_s)
                status = "ok" if proc.returncode == 0 else "failed"
            except subprocess.TimeoutExpired:
                kill_group(proc)
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


def _lane(event: ShowEvent) -> str:
    """Whose turn `event` takes: its participant's, or a newcomer's, the newcomers' (`NEWCOMERS`)."""
    return event.participant if event.earned else NEWCOMERS
