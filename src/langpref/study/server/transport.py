"""The study server's HTTP/1.1 protocol: uvicorn's h11 protocol whose writes of one event-loop step go out in one send.

uvicorn writes a response's status line and headers, then its body, each with its own `send` on the socket, so a
client wakes twice per answer. On a busy machine each wake-up of the client can preempt the server's event loop
inside the send (the kernel runs the woken reader first): the loop waited about 3 ms per send with 20 participants
answering at once on 2 loaded cores, half of its time. Here the writes made during one step of the loop (the headers
and the body of a response) are joined and sent once, right after that step.
"""

from __future__ import annotations

import asyncio
from typing import Any

from uvicorn.protocols.http.h11_impl import H11Protocol

__all__ = ["JoinedWrites", "OneSendH11Protocol"]


class JoinedWrites:
    """An asyncio transport whose `write`s of one loop step are sent as one (everything else is the transport's)."""

    def __init__(self, transport: asyncio.Transport, loop: asyncio.AbstractEventLoop):
        self._transport = transport
        self._loop = loop
        self._held: list[bytes] = []

    def write(self, data: bytes) -> None:
        if not data:
            return
        if not self._held:
            self._loop.call_soon(self.flush)
        self._held.append(bytes(data))

    def writelines(self, chunks: Any) -> None:
        for chunk in chunks:
            self.write(chunk)

    def flush(self) -> None:
        """Send what is held now (the loop does it after the step that wrote it)."""
        if self._held:
            data, self._held = b"".join(self._held), []
            if not self._transport.is_closing():
                self._transport.write(data)

    def close(self) -> None:
        self.flush()
        self._transport.close()

    def write_eof(self) -> None:
        self.flush()
        self._transport.write_eof()

    def abort(self) -> None:
        self._held = []
        self._transport.abort()

    def get_write_buffer_size(self) -> int:
        return self._transport.get_write_buffer_size() + sum(len(b) for b in self._held)

    def __getattr__(self, name: str) -> Any:
        return getattr(self._transport, name)


class OneSendH11Protocol(H11Protocol):
    """uvicorn's h11 protocol over `JoinedWrites`: one send per response (`uvicorn.Config(http=...)`)."""

    def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
        super().connection_made(JoinedWrites(transport, self.loop))  # type: ignore[arg-type]
