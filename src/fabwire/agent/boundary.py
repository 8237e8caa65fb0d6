"""The agent's boundary: one ASGI middleware in front of every route, present and future.

Every HTTP request and WebSocket handshake passes, in this order:
  1. the Host allow-list — `Host` must name this agent: a loopback name or address, the listen address, names
     given with `--allow-host`, and (when listening beyond loopback) any IP address and this computer's name.
     A DNS-rebinding page reaches the agent under the attacker's name and is refused here (403).
  2. the browser check — on every state-changing method (not GET/HEAD/OPTIONS) and every WebSocket handshake a
     present `Origin` must be the agent's own, and a present `Sec-Fetch-Site` must be `same-origin` or `none`
     (403). Slicers, scripts and curl send neither and are unaffected; every current browser sends both.
  3. the access token, when the agent has one — `Authorization: Bearer TOKEN`, `X-Api-Key: TOKEN` (OctoPrint's
     and Moonraker's header, which their clients send) or, for browsers' WebSockets, the subprotocol
     `fabwire.token.TOKEN`; every path but the dashboard's own files (`PUBLIC_PATHS`) needs it (401).
  4. the body — each route declares the bodies it takes (a pydantic/Form/File body, or `openapi_extra`'s
     `requestBody` content); anything else is 415. JSON bodies are read here, at most `JSON_BODY_LIMIT` bytes,
     parsed and checked for depth (400) before the route sees them; uploads are counted as they arrive and cut
     off past `--max-upload` (413); a body that stops arriving for `BODY_IDLE_S`, or that brings under
     `BODY_MIN_RATE` × `BODY_GRACE_S` bytes in any window of `BODY_GRACE_S` after the first (`BodyPace`), ends the
     request (408, `Connection: close`), and what the route held with it.

A route added later is covered by all four without doing anything: the middleware wraps the whole application
and looks the route up in the live route table. Errors are the API's `{"message", "exit_code", "error"}`.
"""

from __future__ import annotations

import asyncio
import contextlib
import hmac
import ipaddress
import json
import logging
import re
import socket
from collections.abc import Awaitable, Callable, Iterable, Iterator, MutableMapping
from dataclasses import dataclass, field
from email.headerregistry import ContentTypeHeader, HeaderRegistry
from typing import TYPE_CHECKING, Any, ClassVar, cast

from fabwire import jsontext
from fabwire.errors import FabwireError, InputError, excerpt

if TYPE_CHECKING:
    from fabwire.agent.session import RequestsFirst

log = logging.getLogger("fabwire.agent")

Scope = MutableMapping[str, Any]
Message = MutableMapping[str, Any]
Receive = Callable[[], Awaitable[Message]]
Send = Callable[[Message], Awaitable[None]]
ASGIApp = Callable[[Scope, Receive, Send], Awaitable[None]]

SAFE_METHODS = frozenset({"GET", "HEAD", "OPTIONS"})
"""RFC 9110 §9.2.1: the methods defined to change nothing; every other method is checked as a write."""

CORS_SIMPLE_TYPES: tuple[tuple[str, str], ...] = (
    ("text/plain", "Fetch standard §4.1 CORS-safelisted Content-Type; HTML form enctype=text/plain; "
                   "what fetch() sends for a string body"),
    ("application/x-www-form-urlencoded", "Fetch standard CORS-safelisted Content-Type; HTML forms' default "
                                          "enctype; curl -d"),
    ("multipart/form-data", "Fetch standard CORS-safelisted Content-Type; HTML form enctype=multipart/form-data; "
                            "FormData bodies"),
)
"""The content types a web page may send to any origin without a CORS preflight: a route that takes none of
them can be written to cross-origin only after a preflight, which this agent never grants."""

TRUSTED_FETCH_SITES = frozenset({"same-origin", "none"})
"""W3C Fetch Metadata Request Headers §2.4 `Sec-Fetch-Site`: "none" is the user typing the URL or a bookmark;
"same-site" is refused too, since another port of localhost is the same site but another program."""

PUBLIC_PATHS: tuple[str, ...] = ("/", "/static/")
"""Paths served without the token: the dashboard's page and files hold no data and ask for the token
(a path ending in "/" covers everything under it, except "/" itself which is only the page)."""

TOKEN_FILE = "access-token"
SUBPROTOCOL = "fabwire"
TOKEN_PREFIX = "fabwire.token."
API_KEY_HEADER = b"x-api-key"
"""OctoPrint REST API "Authorization" section and Moonraker's API-key authorization use this header."""

JSON_BODY_LIMIT = 64 * 1024
"""The largest JSON body: an action's parameters (a Line-us text is the longest) fit many times over."""
MAX_JSON_DEPTH = jsontext.MAX_DEPTH
"""Nesting a parameter object may have; deeper JSON is refused with 400 before anything parses it further."""
MULTIPART_OVERHEAD = 64 * 1024
"""What a multipart upload may carry besides its file (boundaries, part headers, small fields)."""
BODY_IDLE_S = 30.0
"""How long a request's body may stop arriving before the request is ended (408)."""
BODY_GRACE_S = 30.0
"""Seconds of waiting for a body before its pace is checked (a connection that starts slowly still passes), and the
length of each window its pace is then checked over (`BodyPace`)."""
BODY_MIN_RATE = 1024.0
"""Bytes per second a body must bring in every window of `BODY_GRACE_S` past the first (over the time spent waiting
for it): slow Wi-Fi and a Raspberry Pi upload at tens of KiB/s or more; a trickle that only keeps a machine claimed
is far below, however much it sent at first."""

JSON_TYPE = "application/json"
RAW_TYPE = "application/octet-stream"
MULTIPART_TYPE = "multipart/form-data"
FORM_TYPE = "application/x-www-form-urlencoded"


class BoundaryError(FabwireError):
    """A request refused at the boundary; `http_status` is its HTTP status."""

    http_status: ClassVar[int] = 400
    exit_code = InputError.exit_code


class AccessDenied(BoundaryError):
    http_status = 401
    exit_code = 3


class ForeignHost(BoundaryError):
    http_status = 403
    exit_code = 3


class CrossOrigin(BoundaryError):
    http_status = 403
    exit_code = 3


class UnsupportedMediaType(BoundaryError):
    http_status = 415


class BodyTooLarge(BoundaryError):
    http_status = 413


class BodyTimeout(BoundaryError):
    http_status = 408


class BadJSON(BoundaryError):
    http_status = 400


class AgentStopping(BoundaryError):
    """The agent stopped (SIGTERM, Ctrl-C) before a request was answered: uvicorn cancels what still runs once
    its graceful shutdown ends."""

    http_status = 503
    exit_code = 8


# ------------------------------------------------------------------------------------------------ policy


def is_loopback(host: str) -> bool:
    """`localhost`, a `*.localhost` name (RFC 6761 §6.3: always loopback) or a loopback address."""
    host = host.strip("[]").rstrip(".").lower()
    if host == "localhost" or host.endswith(".localhost"):
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def _is_ip(host: str) -> bool:
    try:
        ipaddress.ip_address(host.strip("[]"))
    except ValueError:
        return False
    return True


def normal_host(name: str) -> str:
    """A host name as compared: lower case, no trailing dot, IPv6 without brackets."""
    return name.strip().strip("[]").rstrip(".").lower()


@dataclass(frozen=True)
class Policy:
    """Who may talk to the agent. `hosts`: the names (besides loopback) a `Host` header may carry;
    `any_ip`: any IP address may be the Host (the agent listens beyond loopback, where no rebinding can
    produce an address); `token`: the access token, or None on a loopback agent without one."""

    hosts: frozenset[str] = frozenset()
    any_ip: bool = False
    token: str | None = None
    max_upload_bytes: int = 64 * 1024 * 1024

    @classmethod
    def for_listen(cls, listen_host: str, allow_hosts: Iterable[str] = (), *, token: str | None = None,
                   max_upload_bytes: int = 64 * 1024 * 1024) -> Policy:
        """The policy of an agent listening on `listen_host` (an address or a name), with the owner's extra
        names; a wildcard address adds this computer's names."""
        hosts = {normal_host(h) for h in allow_hosts if normal_host(h)}
        listen = normal_host(listen_host)
        wildcard = listen in ("0.0.0.0", "::", "")
        if not wildcard:
            hosts.add(listen)
        if wildcard:
            name = normal_host(socket.gethostname())
            hosts |= {name, f"{name.partition('.')[0]}.local"}
        return cls(frozenset(hosts), any_ip=not is_loopback(listen_host), token=token,
                   max_upload_bytes=max_upload_bytes)

    def host_allowed(self, host: str) -> bool:
        host = normal_host(host)
        if not host:
            return False
        if is_loopback(host) or host in self.hosts:
            return True
        return self.any_ip and _is_ip(host)


# ------------------------------------------------------------------------------------------------ headers


def header(scope: Scope, name: bytes) -> str:
    """The first value of a request header (names are lower case in ASGI), "" when absent."""
    for key, value in scope.get("headers", []):
        if key == name:
            return bytes(value).decode("latin-1")
    return ""


def split_authority(authority: str) -> tuple[str, int | None] | None:
    """`host[:port]` → (host, port); None when malformed. IPv6 addresses come in brackets."""
    authority = authority.strip()
    if authority.startswith("["):
        host, sep, rest = authority[1:].partition("]")
        if not sep or (rest and not rest.startswith(":")):
            return None
        port_text = rest[1:]
    else:
        host, _, port_text = authority.partition(":")
    if not host or any(c in host for c in "/@ \\"):
        return None
    if port_text and not (port_text.isdigit() and len(port_text) <= 5 and int(port_text) <= 65535):
        return None
    return host, int(port_text) if port_text else None


DEFAULT_PORTS = {"http": 80, "https": 443, "ws": 80, "wss": 443}


def same_origin(origin: str, host_header: str) -> bool:
    """Whether an `Origin` (scheme://host[:port]) names the authority the request was sent to (RFC 6454 §5
    compares scheme too; here host and port decide, since a TLS proxy in front of the agent turns the page's
    https into http, and no other program can serve pages from the agent's own host and port)."""
    scheme, sep, authority = origin.strip().partition("://")
    scheme = scheme.lower()
    if not sep or scheme not in DEFAULT_PORTS:
        return False  # "null" (sandboxed frames, file: pages) and anything odd is not this agent
    theirs, ours = split_authority(authority), split_authority(host_header)
    if theirs is None or ours is None:
        return False
    default = DEFAULT_PORTS[scheme]
    return normal_host(theirs[0]) == normal_host(ours[0]) and (theirs[1] or default) == (ours[1] or default)


def presented_token(scope: Scope) -> str:
    """The token a request carries: Bearer, X-Api-Key, or a `fabwire.token.` WebSocket subprotocol."""
    auth = header(scope, b"authorization")
    if auth[:7].lower() == "bearer ":
        return auth[7:].strip()
    key = header(scope, API_KEY_HEADER).strip()
    if key:
        return key
    for proto in header(scope, b"sec-websocket-protocol").split(","):
        proto = proto.strip()
        if proto.startswith(TOKEN_PREFIX):
            return proto[len(TOKEN_PREFIX):]
    return ""


_MIME_HEADERS = HeaderRegistry()
MAX_CONTENT_TYPE = 256
"""Characters of a Content-Type value read at most (a multipart boundary is at most 70, RFC 2046 §5.1.1); a longer
one is refused unread, which also bounds the parser's work on hostile values."""


def media_type(content_type: str) -> str:
    """The media type of a Content-Type value, lower case, without parameters; "" for an empty value.

    Parsed by the standard library's MIME header parser (`email.headerregistry`, the RFC 2045 Content-Type
    grammar that RFC 9110 §8.3.1 shares: `type "/" subtype *( ";" parameter )`). A value it finds any defect in
    is UnsupportedMediaType (415), never guessed at: a list (`text/plain,application/octet-stream`), a type
    without a subtype, stray separators, control characters."""
    if not content_type.strip():
        return ""
    refusal = UnsupportedMediaType(f"Content-Type {excerpt(content_type, 80)} is not one media type such as "
                                   "application/octet-stream")
    if len(content_type) > MAX_CONTENT_TYPE:
        raise refusal
    try:
        parsed = _MIME_HEADERS("content-type", content_type)
        if parsed.defects:
            raise refusal
        return cast(ContentTypeHeader, parsed).content_type
    except UnsupportedMediaType:
        raise
    except Exception:  # the parser's own failures on hostile values (RecursionError for comments nested
        # hundreds deep, HeaderParseError and IndexError for stray `*` parameters): all mean "not a media type"
        raise refusal from None


def request_media_type(scope: Scope) -> str:
    """The request's media type (see `media_type`); a Content-Type header given more than once is
    UnsupportedMediaType (RFC 9110 §5.3: it is a singleton field, and the two would be read differently)."""
    values = [bytes(v).decode("latin-1") for k, v in scope.get("headers", []) if k == b"content-type"]
    if len(values) > 1:
        raise UnsupportedMediaType(f"send one Content-Type header, not {len(values)}")
    return media_type(values[0]) if values else ""


# ------------------------------------------------------------------------------------------------ JSON


def parse_json(raw: bytes | str, *, what: str = "the body", max_depth: int = MAX_JSON_DEPTH) -> Any:
    """JSON text → value, through the one bounded reader of outside JSON (`fabwire.jsontext`); BadJSON (an
    InputError, 400) for text that is not JSON or nests deeper than `max_depth`."""
    try:
        return jsontext.parse_json(raw, what=what, max_depth=max_depth)
    except InputError as exc:
        raise BadJSON(str(exc)) from None


# ------------------------------------------------------------------------------------------------ routes


@dataclass(frozen=True)
class BodyRule:
    """What a route takes as its body: media types (empty: no body at all) and the largest size."""

    types: frozenset[str] = frozenset()
    limit: int = 0
    raw: bool = False
    """The body is a file as it is (any content type but the CORS-simple ones and JSON)."""
    reasons: tuple[str, ...] = field(default=(), compare=False)


def declared_types(route: Any) -> set[str]:
    """The media types a route declares for its body: FastAPI's body field (Body → JSON, Form, File →
    multipart) and `openapi_extra["requestBody"]["content"]`."""
    types: set[str] = set()
    body_field = getattr(route, "body_field", None)
    if body_field is not None:
        types.add(media_type(getattr(body_field.field_info, "media_type", JSON_TYPE) or JSON_TYPE))
    extra = getattr(route, "openapi_extra", None) or {}
    content = (extra.get("requestBody") or {}).get("content") or {}
    types |= {media_type(t) for t in content}
    return types


def body_rule(route: Any, policy: Policy) -> BodyRule:
    types = declared_types(route)
    if not types:
        return BodyRule()
    limit = 0
    if JSON_TYPE in types or FORM_TYPE in types:
        limit = JSON_BODY_LIMIT
    if MULTIPART_TYPE in types:
        limit = max(limit, policy.max_upload_bytes + MULTIPART_OVERHEAD)
    if RAW_TYPE in types:
        limit = max(limit, policy.max_upload_bytes)
    return BodyRule(frozenset(types), limit, raw=RAW_TYPE in types)


def leaf_routes(routes: Iterable[Any]) -> Iterator[Any]:
    """Every route of a route table in matching order, routers included with `include_router` opened up (newer
    FastAPI keeps an included router as one entry whose `effective_candidates()` are its routes, prefixed)."""
    for route in routes:
        nested = getattr(route, "effective_candidates", None)
        if callable(nested):
            yield from leaf_routes(nested())
        else:
            yield route


def find_route(routes: Iterable[Any], scope: Scope) -> Any | None:
    """The route that will serve `scope` (Starlette's first full match), or None (404/405 follow)."""
    from starlette.routing import Match

    for route in leaf_routes(routes):
        match, _ = route.matches(dict(scope))
        if match == Match.FULL:
            return route
    return None


def check_body_type(rule: BodyRule, given: str, has_body: bool) -> None:
    """UnsupportedMediaType unless the request's media type (`request_media_type`) is one the route takes."""
    if not rule.types:
        if has_body:
            raise UnsupportedMediaType("this request takes no body")
        return
    if rule.raw and given not in {t for t, _ in CORS_SIMPLE_TYPES} and given != JSON_TYPE:
        return  # a file as it is: none, application/octet-stream, image/svg+xml, text/x-gcode …
    if given in rule.types:
        return
    if not given and not has_body:
        return
    wanted = " or ".join(sorted(rule.types))
    if rule.raw:
        wanted = "the file as it is, e.g. Content-Type: application/octet-stream"
    raise UnsupportedMediaType(f"send {wanted}, not {given or 'a body without Content-Type'}"
                               + (" (curl: --json '{…}' or -H 'Content-Type: application/json')"
                                  if JSON_TYPE in rule.types else ""))


# ------------------------------------------------------------------------------------------------ middleware


def _declared_length(scope: Scope) -> int | None:
    text = header(scope, b"content-length").strip()
    return int(text) if text.isdigit() else None


def _has_body(scope: Scope) -> bool:
    length = _declared_length(scope)
    return bool(length) or "chunked" in header(scope, b"transfer-encoding").lower()


class Boundary:
    """The ASGI middleware (see the module's docstring). `router` is the router of the app behind it (its
    `routes` are read at each request, so routes added later are looked up too). `requests_first`, the agent's,
    is told of each reading request (GET, HEAD, OPTIONS) while it is answered, so the polls step aside for it."""

    def __init__(self, app: ASGIApp, *, policy: Policy, router: Any, requests_first: RequestsFirst | None = None
                 ) -> None:
        self.app = app
        self.policy = policy
        self.router = router
        self.requests_first = requests_first
        self._token = policy.token.encode() if policy.token else None

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] not in ("http", "websocket"):
            await self.app(scope, receive, send)
            return
        try:
            self.check_request(scope)
            if scope["type"] == "http" and scope["method"] not in SAFE_METHODS:
                route = find_route(self.router.routes, scope)  # (a request without a body needs no rule)
                rule = body_rule(route, self.policy) if route is not None else BodyRule(limit=JSON_BODY_LIMIT)
                if route is not None:
                    check_body_type(rule, request_media_type(scope), _has_body(scope))
                declared = _declared_length(scope)
                if declared is not None and declared > rule.limit:
                    raise BodyTooLarge(_too_large(rule, declared))
                if rule.types and not rule.raw and MULTIPART_TYPE not in rule.types:
                    receive = await self._buffered(scope, receive, rule)
                else:
                    receive = _Counted(receive, rule)
        except BoundaryError as exc:
            await deny(scope, send, exc)
            return
        first = self.requests_first if scope["type"] == "http" and scope["method"] in SAFE_METHODS else None
        if first is not None:
            first.begin()
        try:
            await self.app(scope, receive, send)
        except asyncio.CancelledError:
            if scope["type"] != "http":
                raise
            # One line and a 503 where the answer has not begun, never a traceback; what the request held
            # (a claimed machine, an upload being checked) was released on the way out.
            log.warning("%s %s: the agent stopped before answering it", scope.get("method", "GET"),
                        scope.get("path", ""))
            with contextlib.suppress(Exception):
                await deny(scope, send, AgentStopping("the agent is stopping: send the request again once it is "
                                                      "back"))
        except Exception as exc:
            from starlette.requests import ClientDisconnect

            if not isinstance(exc, ClientDisconnect):
                raise
            if isinstance(receive, _Counted) and receive.done:  # all of it came: it left while it was checked
                when = f" while its request ({receive.size:,} bytes) was handled, before the answer"
            else:
                when = (f" after {receive.size:,} bytes" if isinstance(receive, _Counted) else "") + \
                    ", before its request was complete"
            log.warning("%s %s: the client went away%s; nothing was kept", scope.get("method", "GET"),
                        scope.get("path", ""), when)
        finally:
            if first is not None:
                first.end()

    def check_request(self, scope: Scope) -> None:
        host = header(scope, b"host")
        parsed = split_authority(host)
        if parsed is None or not self.policy.host_allowed(parsed[0]):
            raise ForeignHost(f"this agent does not answer to the name {host[:100]!r}"
                              + (f": if it is yours, start it with --allow-host {parsed[0][:100]}" if parsed else ""))
        writes = scope["type"] == "websocket" or scope["method"] not in SAFE_METHODS
        if writes:
            origin = header(scope, b"origin")
            if origin and not same_origin(origin, host):
                raise CrossOrigin(f"a page from {origin[:100]} may not use this agent: only its own pages, "
                                  "and programs that send no Origin, may")
            site = header(scope, b"sec-fetch-site").strip().lower()
            if site and site not in TRUSTED_FETCH_SITES:
                raise CrossOrigin(f"a {site} page may not use this agent: only its own pages may")
        if self._token is not None and not _public(scope["path"]):
            presented = presented_token(scope)
            if not hmac.compare_digest(presented.encode(), self._token):
                problem = ("the access token sent is not this agent's" if presented
                           else "this agent needs its access token")
                raise AccessDenied(f"{problem}: send the header 'Authorization: Bearer TOKEN' or 'X-Api-Key: TOKEN' "
                                   f"(the token is in the agent's state directory, file {TOKEN_FILE})")

    async def _buffered(self, scope: Scope, receive: Receive, rule: BodyRule) -> Receive:
        """Read a small body whole (bounded, with the body's timeouts), check JSON, and replay it."""
        chunks: list[bytes] = []
        counted = _Counted(receive, rule)
        while not counted.done:
            message = await counted()
            if message["type"] == "http.disconnect":
                from starlette.requests import ClientDisconnect

                raise ClientDisconnect()
            chunks.append(message.get("body", b""))
        body = b"".join(chunks)
        if body.strip() and request_media_type(scope) == JSON_TYPE:
            parse_json(body)
        replayed = False

        async def replay() -> Message:
            nonlocal replayed
            if not replayed:
                replayed = True
                return {"type": "http.request", "body": body, "more_body": False}
            return await receive()

        return replay


def _too_large(rule: BodyRule, size: int | None) -> str:
    if rule.limit == 0:
        return "this request takes no body"
    what = "the upload" if rule.raw or MULTIPART_TYPE in rule.types else "the body"
    said = f"is {size:,} bytes; the limit is" if size is not None else "is over the limit of"
    return f"{what} {said} {rule.limit:,} bytes" + (" (--max-upload)" if what == "the upload" else "")


class BodyPace:
    """The pace a body must keep, on the clock of the seconds spent waiting for it: nothing is asked during the
    first `grace` seconds (a connection that starts slowly passes); from then on, each successive window of
    `grace` seconds must bring at least `rate` × `grace` bytes. A burst never buys time for later windows, so a
    client that sends most of a file at once and then a byte now and then fails at the end of the first window
    that its trickle does not fill (`BODY_GRACE_S`, `BODY_MIN_RATE`)."""

    def __init__(self, grace: float, rate: float) -> None:
        self.window = max(grace, 1e-3)
        self.rate = rate
        self.start = max(grace, 0.0)
        """When the current window began (seconds of waiting)."""
        self.got = 0
        """Bytes that came in the current window."""

    @property
    def need(self) -> float:
        """The bytes each window must bring."""
        return self.rate * self.window

    def due(self) -> float:
        """The seconds of waiting by which the current window must be full."""
        return self.start + self.window

    def arrived(self, size: int, waited: float) -> None:
        """Count `size` bytes that came after `waited` seconds of waiting (bytes of the grace count for nothing)."""
        if waited >= self.start:
            self.got += size

    def too_slow(self, waited: float) -> bool:
        """Whether a window that ended by `waited` seconds of waiting brought under `need` bytes; windows that
        were full are passed, and the next one begins."""
        while waited >= self.due():
            if self.got < self.need:
                return True
            self.start, self.got = self.due(), 0
        return False


class _Counted:
    """`receive` that raises BodyTooLarge once the body passes the rule's limit, and BodyTimeout when it stops
    arriving for `BODY_IDLE_S` or falls behind `BodyPace` (both reach the route as exceptions, so whatever it held
    is released); `size` is what came, `waited` the seconds spent waiting for it (a route's own work between reads
    is not counted against the client)."""

    def __init__(self, receive: Receive, rule: BodyRule) -> None:
        self.receive = receive
        self.rule = rule
        self.size = 0
        self.waited = 0.0
        self.done = False
        self.pace = BodyPace(BODY_GRACE_S, BODY_MIN_RATE)

    def _slow(self) -> BodyTimeout:
        pace = self.pace
        return BodyTimeout(f"the body arrives too slowly: {pace.got:,} bytes in the last {pace.window:g} s "
                           f"({self.size:,} in all); after the first {pace.window:g} s every {pace.window:g} s must "
                           f"bring at least {pace.need:,.0f} bytes ({pace.rate / 1024:g} KiB/s)")

    async def __call__(self) -> Message:
        if self.done:
            return await self.receive()  # only the disconnect is left to wait for
        if self.pace.too_slow(self.waited):
            raise self._slow()
        slow = self.pace.due() - self.waited
        loop = asyncio.get_running_loop()
        started = loop.time()
        try:
            async with asyncio.timeout(min(BODY_IDLE_S, slow)):
                message = await self.receive()
        except TimeoutError:
            self.waited += loop.time() - started
            if slow < BODY_IDLE_S:
                if self.pace.too_slow(max(self.waited, self.pace.due())):
                    raise self._slow() from None
                return await self()  # the window was full: wait on in the next one
            raise BodyTimeout(f"the body stopped arriving for {BODY_IDLE_S:g} s") from None
        self.waited += loop.time() - started
        if message["type"] == "http.request":
            size = len(message.get("body", b""))
            self.size += size
            self.pace.arrived(size, self.waited)
            if self.size > self.rule.limit:
                raise BodyTooLarge(_too_large(self.rule, None))
            self.done = not message.get("more_body", False)
        return message


KEY_REQUEST_PATH = re.compile(r"^(?:/printers/[^/]+)?/plugin/appkeys/(?:probe|request(?:/[^/]+)?)$")
"""The application-key flow (OctoPrint's Application Keys plugin, `fabwire.agent.appkeys`): an application without
the token asks for it there and gets it only once the owner approves on the dashboard, so it takes no token."""


def _public(path: str) -> bool:
    return any(path == p or (p.endswith("/") and p != "/" and path.startswith(p)) for p in PUBLIC_PATHS) or \
        KEY_REQUEST_PATH.match(path) is not None


CLOSES_CONNECTION: dict[int, str] = {
    408: "RFC 9110 §15.5.9 Request Timeout: the server SHOULD send the `close` connection option, since a 408 "
         "implies it has decided to close the connection rather than continue waiting (the rest of the body may "
         "still be on its way: the connection is in no state to carry another request)",
}
"""The statuses whose answer ends the connection (`Connection: close`, RFC 9112 §9.6), each with its source."""


def connection_headers(status: int) -> dict[str, str]:
    """The `Connection` header an answer with `status` carries: `close` for CLOSES_CONNECTION, else none."""
    return {"connection": "close"} if status in CLOSES_CONNECTION else {}


def error_body(exc: FabwireError) -> bytes:
    return json.dumps({"message": str(exc), "exit_code": exc.exit_code, "error": type(exc).__name__}).encode()


async def deny(scope: Scope, send: Send, exc: BoundaryError) -> None:
    """Answer a refused request (or WebSocket handshake) with the error, before the app sees it."""
    headers = [(b"content-type", b"application/json")]
    if isinstance(exc, AccessDenied):
        headers.append((b"www-authenticate", b"Bearer"))
    headers += [(k.encode(), v.encode()) for k, v in connection_headers(exc.http_status).items()]
    body = error_body(exc)
    headers.append((b"content-length", str(len(body)).encode()))
    if scope["type"] == "http":
        prefix = "http"
    elif "websocket.http.response" in scope.get("extensions", {}):
        prefix = "websocket.http"
    else:  # a server without the denial-response extension: close the handshake (HTTP 403)
        await send({"type": "websocket.close", "code": 4403 if exc.http_status == 403 else 4401,
                    "reason": str(exc)[:120]})
        return
    await send({"type": f"{prefix}.response.start", "status": exc.http_status, "headers": headers})
    await send({"type": f"{prefix}.response.body", "body": body})
