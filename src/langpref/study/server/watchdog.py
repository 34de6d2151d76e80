"""The `--on-show` hook's watchdog: a small process that kills the replays in flight when the server ends, even by
`kill -9` (`langpref.study.server.hook`), and the kill of one run's process group."""

from __future__ import annotations

import logging
import os
import signal
import subprocess
import sys
import threading

log = logging.getLogger("langpref.study")


def kill_group(proc: subprocess.Popen[bytes]) -> None:
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
