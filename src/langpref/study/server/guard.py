"""What the study server refuses before a request reaches the study, each as a one-line 4xx `{"error": ...}`:

- a body over `MAX_BODY`: by its `Content-Length` before any of it is read, and a body without one (chunked) counted
  as it streams in, stopping at the limit (`read_body`), so a large upload never sits in memory;
- JSON nested deeper than `MAX_DEPTH` or holding more than `MAX_VALUES` values (`decode_json`; measured without
  recursion, the count stopping at the limit), and text with lone UTF-16 surrogates (they cannot be stored as UTF-8;
  `langpref.study.protocol.flow.clean_text` refuses them). An answer's body is decoded and checked before the
  participant's lock is taken, so a body made to be slow (21,000 empty lists fit in 64 KiB) holds no other participant
up;
- a `Host` header that is not one of this study's names (`HostCheck`): a page of another site that a DNS-rebinding
  attack points at the server would otherwise reach it as "same origin";
- a POST whose `Origin` (or `Referer`) is another site's page (`cross_site`);
- too many wrong resume codes from one client (`RateLimiter`, keyed by `client_key`): one client cannot lock resume
  for the others; and too many sign-ups from one client (`study serve --signups-per-client`): made-up participants
  cannot outnumber real ones in the turns of the robot (`--on-show`) and of the simulator. The client is the
  address that connects; `X-Forwarded-For` names it only when that address is a proxy the lab named
  (`TrustedProxies`, `--trusted-proxy`), so no client can pass itself off as many.
"""

from __future__ import annotations

import ipaddress
import json
import math
import threading
import time
from collections import OrderedDict, deque
from collections.abc import Iterable
from typing import Any
from urllib.parse import urlsplit

MAX_BODY = 64 * 1024
"""Largest request body taken, in bytes."""
MAX_DEPTH = 32
"""Deepest nesting of lists and objects a JSON body may have (the contract needs 3)."""
MAX_VALUES = 1000
"""Most values a JSON body may hold, counting every list item and object member at every level (the largest answer
of the contract, the Study-2 survey of a study of several kinds, holds well under 200)."""
LOCAL_HOSTS = ("localhost", "127.0.0.1", "::1")


class HttpError(Exception):
    """An error answered as `{"error": message}` with `status` (and `headers`)."""

    def __init__(self, status: int, message: str, headers: dict[str, str] | None = None):
        super().__init__(message)
        self.status = status
        self.message = message
        self.headers = headers


def _too_large() -> HttpError:
    return HttpError(413, f"the body is over {MAX_BODY // 1024} KiB")


async def read_body(request) -> bytes:
    """The request's body, refused (413) when its Content-Length says it is over `MAX_BODY` (nothing of it is read)
    or, without one, as soon as the bytes received pass it."""
    length = request.headers.get("content-length")
    if length is not None:
        if not length.strip().isascii() or not length.strip().isdigit():
            raise HttpError(400, "the Content-Length header is not a number")
        if int(length) > MAX_BODY:
            raise _too_large()
    chunks, size = [], 0
    async for chunk in request.stream():
        size += len(chunk)
        if size > MAX_BODY:
            raise _too_large()
        chunks.append(chunk)
    return b"".join(chunks)


def depth(value: Any) -> int:
    """How deeply lists and objects nest in `value` (0 for a scalar), without recursion."""
    deepest, todo = 0, [(value, 1)]
    while todo:
        item, level = todo.pop()
        children = item.values() if isinstance(item, dict) else item if isinstance(item, list) else None
        if children is None:
            continue
        deepest = max(deepest, level)
        todo.extend((c, level + 1) for c in children if isinstance(c, (dict, list)))
    return deepest


def check_shape(value: Any, max_depth: int = MAX_DEPTH, max_values: int = MAX_VALUES) -> None:
    """Refuse (400) `value` nested deeper than `max_depth` or holding more than `max_values` list items and object
    members in all. Without recursion, and in at most `max_values` steps: a container is counted by its length
    before any of its items is looked at."""
    todo, seen = [(value, 1)], 0
    while todo:
        item, level = todo.pop()
        children = item.values() if isinstance(item, dict) else item if isinstance(item, list) else None
        if children is None:
            continue
        if level > max_depth:
            raise HttpError(400, f"the body is nested too deeply (more than {max_depth} levels)")
        seen += len(children)
        if seen > max_values:
            raise HttpError(400, f"the body holds too many values (more than {max_values}); send one answer")
        todo.extend((c, level + 1) for c in children if isinstance(c, (dict, list)))


def decode_json(body: bytes, allow_empty: bool = False) -> Any:
    """The JSON of a body (at most `MAX_BODY` bytes, nested at most `MAX_DEPTH` deep, at most `MAX_VALUES` values:
    `check_shape`), or a 4xx HttpError."""
    if len(body) > MAX_BODY:
        raise _too_large()
    if allow_empty and not body.strip():
        return {}
    try:
        data = json.loads(body, parse_constant=_no_constant)
    except RecursionError:
        raise HttpError(400, "the body is nested too deeply") from None
    except (ValueError, UnicodeDecodeError) as exc:  # JSONDecodeError, and integers of over 4300 digits
        line = " ".join(str(exc).split())[:80]
        raise HttpError(400, f"the body is not valid JSON ({exc.__class__.__name__}: {line})") from None
    check_shape(data)
    return data


def _no_constant(name: str):
    raise ValueError(f"{name} is not a JSON number")


# ---- Host and Origin ----


def host_name(value: str) -> str:
    """The name of a Host header (or a netloc) without its port, lower case: `[::1]:8000` -> `::1`."""
    value = value.strip().lower()
    if value.startswith("["):
        return value[1 : value.find("]")] if "]" in value else value[1:]
    if value.count(":") == 1:
        value = value.split(":", 1)[0]
    return value.rstrip(".")


def _is_ip(name: str) -> bool:
    try:
        ipaddress.ip_address(name)
    except ValueError:
        return False
    return True


class HostCheck:
    """The Host names a request may carry: `localhost` (and `*.localhost`), 127.0.0.1, ::1, the address the server
    listens on, the hosts of the allowed origins, and `allowed`. An address (`192.168.1.5`) is always taken: a page
    can only reach the server under an address by being served from it, while a DNS-rebinding page reaches it under
    its own name, which is not on the list."""

    def __init__(self, allowed: Iterable[str] = (), bind_host: str | None = None, origins: Iterable[str] = ()):
        names = {*LOCAL_HOSTS, *(host_name(h) for h in allowed)}
        if bind_host:
            names.add(host_name(bind_host))
        names.update(host_name(urlsplit(o).netloc) for o in origins if "://" in o)
        self.names = frozenset(n for n in names if n)

    def refused(self, header: str | None) -> str | None:
        """Why a request with Host `header` is refused (None when it is not); a request without one passes."""
        if header is None:
            return None
        name = host_name(header)
        if name in self.names or name.endswith(".localhost") or _is_ip(name):
            return None
        return (
            f"this server is not {name[:80]!r}: open the study at the address it printed (to serve it under this "
            "name, start it with --allowed-hosts NAME)"
        )


def cross_site(headers, allowed: set[str]) -> str | None:
    """Why a state-changing request comes from another site's page (None when it does not): its Origin (or, without
    one, its Referer) must be the host it was sent to, or one of `allowed`. Requests of tools, which send neither,
    pass: they hold a token or create only a participant, and no browser page of another site can make them."""
    origin = headers.get("origin")
    if origin is None and headers.get("referer"):
        parts = urlsplit(headers["referer"])
        origin = f"{parts.scheme}://{parts.netloc}"
    if origin is None:
        return None
    origin = origin.strip().rstrip("/").lower()
    if origin in allowed:
        return None
    netloc = urlsplit(origin).netloc if "://" in origin else ""
    host = (headers.get("host") or "").strip().lower()
    if netloc and netloc == host:
        return None
    return (
        f"cross-site request refused: the page at {origin[:100]} is not this study's; open the study at its own "
        "address (behind a proxy that rewrites Host, list its address in allowed_origins)"
    )


# ---- rate limits ----


def client_key(host: str | None) -> str:
    """Who a request comes from, for rate limits: its address, an IPv6 address by its /64 network (one machine's
    share); requests whose address is not known share one key."""
    if not host:
        return "?"
    try:
        address = ipaddress.ip_address(host)
    except ValueError:
        return host[:100]
    if isinstance(address, ipaddress.IPv6Address):
        if address.ipv4_mapped is not None:
            return str(address.ipv4_mapped)
        return str(ipaddress.ip_network(f"{address}/64", strict=False))
    return str(address)


class RateLimiter:
    """At most `limit` events per `window_s` seconds per key. Memory is bounded: at most `max_keys` keys are kept
    (the one seen longest ago forgotten first), each with at most `limit` times. Thread-safe."""

    def __init__(self, limit: int, window_s: float = 60.0, max_keys: int = 10_000):
        self.limit, self.window_s, self.max_keys = limit, window_s, max_keys
        self._events: OrderedDict[str, deque[float]] = OrderedDict()
        self._lock = threading.Lock()

    def _recent(self, key: str, now: float) -> deque[float] | None:
        times = self._events.get(key)
        if times is not None:
            while times and now - times[0] >= self.window_s:
                times.popleft()
        return times

    def blocked(self, key: str, now: float | None = None) -> bool:
        """Whether `key` has had `limit` events in the last `window_s` seconds."""
        now = time.monotonic() if now is None else now
        with self._lock:
            times = self._recent(key, now)
            return times is not None and len(times) >= self.limit

    def take(self, key: str, now: float | None = None) -> int:
        """Count one event of `key` if it has had fewer than `limit` in the window: 0; else, counting nothing, the
        whole seconds until it may have one (for Retry-After). Checked and counted at once, so concurrent requests
        cannot pass together."""
        now = time.monotonic() if now is None else now
        with self._lock:
            times = self._recent(key, now)
            if times is not None and len(times) >= self.limit:
                return max(1, math.ceil(times[0] + self.window_s - now))
            self._add(key, now)
        return 0

    def add(self, key: str, now: float | None = None) -> None:
        """Count one event of `key`."""
        now = time.monotonic() if now is None else now
        with self._lock:
            self._add(key, now)

    def _add(self, key: str, now: float) -> None:
        """Count one event of `key` (call with `_lock` held)."""
        times = self._recent(key, now)
        if times is None:
            times = self._events[key] = deque(maxlen=self.limit)
            while len(self._events) > self.max_keys:
                self._events.popitem(last=False)
        self._events.move_to_end(key)
        times.append(now)


class TrustedProxies:
    """The reverse proxies (addresses or networks, `--trusted-proxy`) whose `X-Forwarded-For` header names the client.
    None by default: the address that connects is the client, whatever header it sends (any process on the server's
    machine, or any client of a proxy that passes the header on, could otherwise name a new address per request)."""

    def __init__(self, proxies: Iterable[str] = ()):
        self.networks = tuple(ipaddress.ip_network(p.strip(), strict=False) for p in proxies)

    @staticmethod
    def check(value: str) -> str:
        """`value` as an address or network (`127.0.0.1`, `10.0.0.0/24`, `::1`); ValueError otherwise."""
        value = value.strip()
        return str(ipaddress.ip_network(value, strict=False) if "/" in value else ipaddress.ip_address(value))

    def trusts(self, host: str | None) -> bool:
        """Whether `host` (an address) is one of the named proxies."""
        if not self.networks or not host:
            return False
        try:
            address = ipaddress.ip_address(host)
        except ValueError:
            return False
        if isinstance(address, ipaddress.IPv6Address) and address.ipv4_mapped is not None:
            address = address.ipv4_mapped
        return any(address.version == net.version and address in net for net in self.networks)

    def client(self, peer: str | None, forwarded: Iterable[str] = ()) -> str | None:
        """Who sent a request that reached the server from `peer` with `X-Forwarded-For` values `forwarded`: `peer`
        unless it is a named proxy; then the last address of the chain that is not one (each proxy appends the
        address it was reached from, so the addresses after the first untrusted one are the proxies' own)."""
        if not self.trusts(peer):
            return peer
        hops = [_forwarded_host(h) for value in forwarded for h in value.split(",")]
        hops = [h for h in hops if h]
        for hop in reversed(hops):
            if not self.trusts(hop):
                return hop
        return hops[0] if hops else peer


def _forwarded_host(hop: str) -> str:
    """An address of X-Forwarded-For without the port some proxies add: `[::1]:80` -> `::1`, `1.2.3.4:80` ->
    `1.2.3.4` (an IPv6 address without brackets is taken whole)."""
    hop = hop.strip()[:100]
    if hop.startswith("["):
        return hop[1 : hop.find("]")] if "]" in hop else hop[1:]
    if hop.count(":") == 1:
        return hop.split(":", 1)[0]
    return hop
