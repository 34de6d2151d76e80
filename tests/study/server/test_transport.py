"""The study server sends a response's headers and body in one send (`langpref.study.server.transport`): the writes of
one event-loop step are joined, in order, and sent right after it; a close sends what is held first, an abort drops it;
a real server answers over it as before."""

from __future__ import annotations

import asyncio
import socket

import httpx

from langpref.study.server.transport import JoinedWrites


class FakeTransport:
    def __init__(self):
        self.sent: list[bytes] = []
        self.closed = False
        self.aborted = False

    def write(self, data: bytes) -> None:
        self.sent.append(data)

    def is_closing(self) -> bool:
        return self.closed

    def close(self) -> None:
        self.closed = True

    def abort(self) -> None:
        self.aborted = True

    def get_write_buffer_size(self) -> int:
        return 0

    def get_extra_info(self, name: str, default=None):
        return {"peername": ("127.0.0.1", 1)}.get(name, default)


def test_writes_of_one_step_go_out_as_one_send_in_order():
    async def main() -> tuple[FakeTransport, list[list[bytes]]]:
        raw = FakeTransport()
        joined = JoinedWrites(raw, asyncio.get_running_loop())
        joined.write(b"HTTP/1.1 200 OK\r\n\r\n")
        joined.write(b"")
        joined.writelines([b'{"a":', b"1}"])
        assert raw.sent == [] and joined.get_write_buffer_size() == len(b'HTTP/1.1 200 OK\r\n\r\n{"a":1}')
        await asyncio.sleep(0)
        seen = [list(raw.sent)]
        joined.write(b"next")
        joined.close()  # what is held goes out before the close
        seen.append(list(raw.sent))
        assert joined.get_extra_info("peername") == ("127.0.0.1", 1)  # the rest is the transport's
        return raw, seen

    raw, seen = asyncio.run(main())
    assert seen[0] == [b'HTTP/1.1 200 OK\r\n\r\n{"a":1}']
    assert seen[1] == [b'HTTP/1.1 200 OK\r\n\r\n{"a":1}', b"next"] and raw.closed


def test_an_abort_drops_what_is_held():
    async def main() -> FakeTransport:
        raw = FakeTransport()
        joined = JoinedWrites(raw, asyncio.get_running_loop())
        joined.write(b"never sent")
        joined.abort()
        await asyncio.sleep(0)
        return raw

    raw = asyncio.run(main())
    assert raw.sent == [] and raw.aborted


def test_the_server_answers_a_response_in_one_segment(study_state):
    """Over a real socket: one recv gets the whole response (status line, headers and body), keep-alive works."""
    from langpref.study.server.serve import BackgroundServer

    with BackgroundServer(study_state) as url:
        host, port = url.removeprefix("http://").split(":")
        with socket.create_connection((host, int(port)), timeout=10) as sock:
            for _ in range(2):  # the same connection twice
                sock.sendall(f"GET /healthz HTTP/1.1\r\nHost: {host}:{port}\r\n\r\n".encode())
                data = sock.recv(65536)
                head, _, body = data.partition(b"\r\n\r\n")
                length = int(
                    next(h for h in head.split(b"\r\n") if h.lower().startswith(b"content-length")).split(b":")[1]
                )
                assert head.startswith(b"HTTP/1.1 200") and len(body) == length > 0
        assert httpx.get(f"{url}/healthz").status_code == 200
