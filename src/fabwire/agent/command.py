"""`fabwire serve`: the agent with its API and dashboard on one port (and, with --mqtt, the MQTT bridge)."""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import functools
import gc
import ipaddress
import logging
import signal
import socket
import sys
import tempfile
import time
from collections.abc import Callable, Coroutine, Iterator
from pathlib import Path
from typing import Any

import click

from fabwire import __version__
from fabwire.agent.auth import TOKEN_FILE, is_loopback, load_or_create_token
from fabwire.agent.boundary import Policy, normal_host, split_authority
from fabwire.agent.core import KINDS, Agent, DeviceSpec, demo_id
from fabwire.agent.terminal import Terminal
from fabwire.checks import ASCII_BLANKS
from fabwire.cli_support import App, FiniteRange, pass_app
from fabwire.errors import FabwireError, InputError, excerpt
from fabwire.mqtt.options import BrokerURL
from fabwire.simoptions import ListenAddress, parse_listen
from fabwire.transport.tcp import listen_failure

DEFAULT_PORT = 8765
DEMO_DEVICES = (("printer", "xyz"), ("line-us", "lineus"), ("mmu", "mmu"))
ANNOUNCEMENT = "fabwire agent listening on "
MAX_UPLOAD_MB = 100 * 1024.0
"""The largest --max-upload: 100 GiB, beyond any print or drawing file."""
MAX_RETENTION_H = 100 * 365 * 24.0
"""The longest --retention: a hundred years (a larger number would overflow the time arithmetic)."""
MAX_SPEED = 10_000.0
"""The fastest --demo simulation: a print of hours in a second."""

SERVER = f"fabwire/{__version__}"
"""The agent's Server header (RFC 9110 §10.2.4), on every answer: a client of a machine pointed at the agent's port
by mistake names it from this (`fabwire.transport.peers`)."""
CONNECTION_SETTINGS: dict[str, Any] = {
    "timeout_keep_alive": 5,        # uvicorn's default: an idle keep-alive connection is closed after 5 s
    "limit_concurrency": 1000,      # uvicorn answers 503 beyond this many connections and tasks
    "h11_max_incomplete_event_size": 16 * 1024,  # a request line and headers larger than this are a 400
    "ws_max_size": 64 * 1024,       # the WebSocket's messages from clients are ignored: no need for 16 MiB
    "ws_ping_interval": 20.0,
    "ws_ping_timeout": 20.0,
    "timeout_graceful_shutdown": 5,
}
"""uvicorn's own connection settings (uvicorn docs, "Settings: Resource Limits / Timeouts")."""
HEAD_TIMEOUT_S = 10.0
"""A connection must complete its request line and headers this soon after opening (or after its previous
answer), or it is closed: half-sent requests (slowloris) cannot hold the agent's connections. The rest of a
refused body is read and dropped (so the client sees the answer) for as long, no longer."""
OPEN_FILES = 4096
"""The soft limit on open files the agent raises itself to (within the hard limit): above limit_concurrency."""


def default_state_dir() -> Path:
    """Where the platform keeps application state (history, uploads, the access token)."""
    import platformdirs

    return Path(platformdirs.user_state_dir("fabwire"))


def configured_devices(path: Path | None) -> list[DeviceSpec]:
    """The named devices of the config file, as specs the agent monitors."""
    from fabwire.config import load_devices

    return [DeviceSpec(d.name, d.kind.name, d.endpoint.url, d.options)  # type: ignore[arg-type]
            for d in load_devices(path).values()]


def device_option_form(text: str, index: int) -> DeviceSpec:
    """`--device KIND=ADDRESS` or `--device NAME:KIND=ADDRESS` split into its parts (the name and address are not
    checked yet: `checked_device`); an InputError when it has neither form."""
    head, sep, address = text.partition("=")
    name, _, kind = head.rpartition(":")
    if not sep or kind not in KINDS or not address:
        raise InputError(f"--device takes KIND=ADDRESS or NAME:KIND=ADDRESS with KIND one of {', '.join(KINDS)}, "
                         f"not {excerpt(text, 60)}")
    return DeviceSpec(name or f"{kind}-{index}", kind, address)


def checked_device(spec: DeviceSpec) -> DeviceSpec:
    """`spec` if its name and address pass the checks `fabwire devices add` makes (`fabwire.checks.RULES`): the
    same InputError, in the same words, otherwise."""
    from fabwire.config import check_device_name
    from fabwire.devices import KINDS as DEVICE_KINDS
    from fabwire.transport.urls import parse_url

    check_device_name(spec.name)
    parse_url(spec.address, DEVICE_KINDS[spec.kind])
    return dataclasses.replace(spec, address=spec.address.strip(ASCII_BLANKS))  # as parse_url reads it


def one_each(specs: list[DeviceSpec]) -> None:
    """Refuse (InputError) a name or a machine given twice among the config file's devices and the `--device`
    options, in the words the agent uses when one is added twice (`Agent.add_device`): a second name would hide
    the machine it names, a second session would talk to one machine twice."""
    from fabwire.devices import KINDS as DEVICE_KINDS
    from fabwire.transport.sameness import Machine, machines_of, same_machine
    from fabwire.transport.urls import parse_url

    names: dict[str, DeviceSpec] = {}
    for spec in specs:
        if spec.name in names:
            raise InputError(f"a device named {excerpt(spec.name, 60)} is given twice (--device or devices.toml)")
        names[spec.name] = spec
    reached = machines_of([parse_url(spec.address, DEVICE_KINDS[spec.kind]) for spec in specs])
    seen: list[tuple[str, frozenset[Machine]]] = []
    for spec, keys in zip(specs, reached, strict=True):
        earlier = same_machine(keys, [(name, theirs) for name, theirs in seen if names[name].kind == spec.kind])
        if earlier is not None:
            raise InputError(f"{excerpt(spec.address, 60)} is given twice, as {earlier!r} and {spec.name!r}: one "
                             "machine is monitored once")
        seen.append((spec.name, keys))


def parse_device_option(text: str, index: int) -> DeviceSpec:
    """`--device KIND=ADDRESS` or `--device NAME:KIND=ADDRESS`, its name and address checked."""
    return checked_device(device_option_form(text, index))


def _usage(convert: Any) -> Any:
    """A click callback that turns the parser's InputError into a usage error (exit 2) naming the option."""

    def callback(ctx: click.Context, param: click.Parameter, value: Any) -> Any:
        try:
            return convert(value)
        except InputError as exc:
            raise click.BadParameter(str(exc), ctx, param) from None

    return callback


def _listen(text: str) -> ListenAddress:
    return parse_listen(text, DEFAULT_PORT)


def _devices(texts: tuple[str, ...]) -> list[DeviceSpec]:
    return [device_option_form(text, i) for i, text in enumerate(texts, 1)]


def _allow_hosts(texts: tuple[str, ...]) -> tuple[str, ...]:
    """Host names (or addresses) the owner reaches the agent by, as a browser puts them in `Host`."""
    names = []
    for text in texts:
        parsed = split_authority(text)
        name = normal_host(parsed[0]) if parsed and parsed[1] is None else ""
        if not name or len(name) > 253 or not all(c.isalnum() or c in "-._:" for c in name):
            raise InputError(f"--allow-host takes a host name such as printers.lan, not {excerpt(text, 60)}")
        names.append(name)
    return tuple(names)


def _bind(host: str, port: int) -> socket.socket:
    """The agent's listening socket; on the IPv6 wildcard `::` a dual-stack one (IPV6_V6ONLY off, RFC 3493
    section 5.3) where the system has them, so IPv4 clients reach it as they do `0.0.0.0`."""
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    dual = family == socket.AF_INET6 and _is_wildcard(host) and socket.has_dualstack_ipv6()
    try:
        return socket.create_server((host, port), family=family, reuse_port=False, dualstack_ipv6=dual)
    except OSError as exc:
        raise listen_failure(exc, host, port) from None


def _is_wildcard(host: str) -> bool:
    try:
        return ipaddress.ip_address(host).is_unspecified
    except ValueError:
        return False


OPEN_AT: tuple[tuple[str, str, str], ...] = (
    ("0.0.0.0", "127.0.0.1, then every other IPv4 address of this computer", "ip(7) INADDR_ANY"),
    ("::, dual-stack", "127.0.0.1 and [::1], then every other IPv4 and IPv6 address of this computer",
     "ipv6(7) IPV6_V6ONLY off; RFC 3493 section 5.3"),
    ("::, IPv6 only", "[::1], then every other IPv6 address of this computer", "ipv6(7) IPV6_V6ONLY on"),
    ("one address", "none besides the one announced: it is the address to open", "ip(7), ipv6(7)"),
)
"""What `serve` prints to open besides the listening address, by what it listens on: (listen, printed, source).
IPv6 link-local addresses are left out (a browser cannot open one: its URL would need a zone id)."""


def open_at(sock: socket.socket) -> list[str]:
    """The URLs a browser opens the agent at when `sock` listens on a wildcard address (`OPEN_AT`), else []."""
    host, port = sock.getsockname()[:2]
    if not _is_wildcard(host):
        return []
    versions = [4] if sock.family == socket.AF_INET else [6]
    if sock.family == socket.AF_INET6 and not sock.getsockopt(socket.IPPROTO_IPV6, socket.IPV6_V6ONLY):
        versions = [4, 6]
    found = [a for a in _addresses() if a.version in versions]
    found.sort(key=lambda a: (not a.is_loopback, a.version))
    return [f"http://{a}:{port}/" if a.version == 4 else f"http://[{a}]:{port}/" for a in found]


def _addresses() -> list[ipaddress.IPv4Address | ipaddress.IPv6Address]:
    """This computer's addresses (its interfaces'), link-local IPv6 ones left out."""
    import ifaddr

    found: dict[ipaddress.IPv4Address | ipaddress.IPv6Address, None] = {}
    for adapter in ifaddr.get_adapters():
        for address in adapter.ips:
            text = address.ip if isinstance(address.ip, str) else address.ip[0]
            with contextlib.suppress(ValueError):
                ip = ipaddress.ip_address(text)
                if not (ip.version == 6 and ip.is_link_local):
                    found[ip] = None
    return list(found)


def _bridge(url: str | None, user: str | None, password: str | None, tls: bool, discovery: str = "device") -> Any:
    """The MQTT bridge's starter, checked before anything else starts (its module ships with fabwire[mqtt])."""
    if url is None:
        return None
    try:
        from fabwire.mqtt.bridge import run_bridge  # type: ignore[import-not-found,unused-ignore]
    except ImportError:
        raise InputError("MQTT support not installed: pip install 'fabwire[mqtt]'") from None

    def start(agent: Agent, dashboard_url: str, passing: frozenset[str] = frozenset(),
              passing_agent: bool = False, terminal: Any = None) -> Coroutine[Any, Any, None]:
        def linked(bridge: Any) -> None:
            bridge.dashboard_url = dashboard_url
            bridge.discovery_mode = discovery
            bridge.passing = passing
            bridge.passing_agent = passing_agent

            def connected(text: str) -> None:
                if terminal is not None:
                    terminal.broker_connected()
                click.echo(f"fabwire agent {text}")

            bridge.on_connected = connected
            if terminal is not None:
                bridge.on_trouble = terminal.broker_trouble

        result: Coroutine[Any, Any, None] = run_bridge(agent, url, username=user, password=password, tls=tls,
                                                       on_bridge=linked)
        return result

    return start


@click.command("serve")
@click.option("--listen", default=f"127.0.0.1:{DEFAULT_PORT}", show_default=True, metavar="HOST:PORT",
              callback=_usage(_listen),
              help="Where the API and dashboard listen; any address but loopback needs the access token.")
@click.option("--allow-host", "allow_hosts", multiple=True, metavar="NAME", callback=_usage(_allow_hosts),
              help="A name you reach the agent by (repeatable), e.g. printers.lan; loopback names and the "
                   "listen address are always allowed, other names are refused (DNS rebinding).")
@click.option("--device", "devices", multiple=True, metavar="[NAME:]KIND=ADDRESS", callback=_usage(_devices),
              help="Monitor this device too (repeatable), besides the config file's named devices.")
@click.option("--config", "config", type=click.Path(dir_okay=False, path_type=Path),
              help="Named devices file (default: fabwire's devices.toml).")
@click.option("--state-dir", type=click.Path(file_okay=False, path_type=Path),
              help="History, uploads and the access token (default: the platform's state directory).")
@click.option("--demo", is_flag=True, help="Start the three simulators and monitor them; a print, a drawing and an "
                                          "MMU tool change start when the dashboard is first opened (history in a "
                                          "temporary directory).")
@click.option("--speed", type=FiniteRange(min=0.5, max=MAX_SPEED), default=30.0, show_default=True,
              help="With --demo: simulated time runs this many times faster.")
@click.option("--retention", type=FiniteRange(min=0.01, max=MAX_RETENTION_H), default=24.0, show_default=True,
              metavar="HOURS",
              help="Keep history this long.")
@click.option("--max-upload", type=FiniteRange(min=0.001, max=MAX_UPLOAD_MB), default=64.0, show_default=True,
              metavar="MB",
              help="Largest upload accepted.")
@click.option("--token/--no-token", "token", default=None,
              help="Require the access token (default: only when listening beyond loopback, where it is "
                   "always required).")
@click.option("--mqtt", "mqtt_url", type=BrokerURL(), help="Also publish to an MQTT broker (mqtt://host[:port]).")
@click.option("--mqtt-user", help="MQTT user name.")
@click.option("--mqtt-password", help="MQTT password (or FABWIRE_MQTT_PASSWORD).", envvar="FABWIRE_MQTT_PASSWORD")
@click.option("--mqtt-tls", is_flag=True, help="Connect to the broker with TLS.")
@click.option("--mqtt-discovery", type=click.Choice(["device", "entity"]), default="device", show_default=True,
              help="Home Assistant discovery: one message per machine (Home Assistant 2024.11 or newer), or one per "
                   "entity (older versions).")
@click.option("--notify", "notify_urls", multiple=True, metavar="URL", envvar="FABWIRE_NOTIFY",
              help="Send print finished/failed/cancelled, MMU errors waiting and machines gone offline to this "
                   "Apprise URL (repeatable): ntfy://topic, tgram://bot/chat, mailto://…, json://host/path …")
@click.option("--notify-offline-after", type=FiniteRange(min=0.0), default=60.0, show_default=True,
              metavar="SECONDS", help="With --notify: how long a machine must be unreachable to be announced.")
@pass_app
def serve(app: App, listen: ListenAddress, allow_hosts: tuple[str, ...], devices: list[DeviceSpec],
          config: Path | None, state_dir: Path | None, demo: bool, speed: float, retention: float,
          max_upload: float, token: bool | None, mqtt_url: str | None, mqtt_user: str | None,
          mqtt_password: str | None, mqtt_tls: bool, mqtt_discovery: str, notify_urls: tuple[str, ...],
          notify_offline_after: float) -> None:
    """Watch a bench of machines: a live dashboard, an HTTP API with history and jobs, one agent.

    Open the printed address in a browser. The API is described at /api/v1/openapi.json.
    """
    address = listen
    local = is_loopback(address.host)
    if token is False and not local:
        raise InputError(f"refusing to listen on {address.host} without an access token: anyone on the network "
                         "could run the machines (leave out --no-token, or listen on 127.0.0.1)")
    bridge = _bridge(mqtt_url, mqtt_user, mqtt_password, mqtt_tls, mqtt_discovery)
    notifier = _notifier(notify_urls, notify_offline_after)
    specs = [checked_device(spec) for spec in devices]  # as `devices add` refuses them: exit 4, one line
    if not demo:
        specs = configured_devices(config) + specs
    one_each(specs)
    demo_dir = tempfile.TemporaryDirectory(prefix="fabwire-demo-") if demo and state_dir is None else None
    directory = state_dir or (Path(demo_dir.name) if demo_dir else default_state_dir())
    sock = _bind(address.host, address.port)  # a bad address fails before a token is made for it
    try:
        secret = None
        if token or not local:
            secret, created = load_or_create_token(directory)
            if created:
                click.echo(f"access token (shown once; kept in {directory / TOKEN_FILE}): {secret}", err=True)
            else:
                click.echo(f"access token: the one in {directory / TOKEN_FILE}", err=True)
        policy = Policy.for_listen(address.host, allow_hosts, token=secret,
                                   max_upload_bytes=int(max_upload * 1024 * 1024))
        if bridge is not None and demo_dir is not None:  # a new agent id each run: it leaves no trace
            bridge = functools.partial(bridge, passing_agent=True)
        interrupted = _run(_serve(sock, specs, directory, demo, speed, retention * 3600.0, policy, bridge,
                                  notifier))
    finally:
        sock.close()
        if demo_dir is not None:
            demo_dir.cleanup()
    if interrupted:
        raise KeyboardInterrupt  # after the clean shutdown: the CLI's "interrupted" exit code


def _freeze_startup_objects() -> None:
    """Leave what start-up made (modules, the application, the sessions) out of the garbage collector's rounds
    from now on: a full round then walks only what the polls made since, and its pause, during which no request
    is answered, stays short however many machines the agent has."""
    gc.collect()
    gc.freeze()


def _notifier(urls: tuple[str, ...], offline_after_s: float) -> Any:
    """The notifier for `--notify`, its URLs checked before anything starts; None without any."""
    if not urls:
        return None
    from fabwire.agent.notify import Notifier

    return Notifier(urls, offline_after_s=offline_after_s)


def _run(main: Coroutine[Any, Any, bool]) -> bool:
    """On uvloop where it is installed: a bench of machines costs a fifth less CPU per poll."""
    try:
        import uvloop
    except ImportError:
        return asyncio.run(main)
    return uvloop.run(main)


async def _serve(sock: socket.socket, specs: list[DeviceSpec], state_dir: Path, demo: bool, speed: float,
                 retention_s: float, policy: Policy, bridge: Any, notifier: Any = None) -> bool:
    """Serve until a signal; True when it was SIGINT (Ctrl-C), False for SIGTERM (a service manager's stop)."""
    import uvicorn

    from fabwire.agent.advertise import Advertiser
    from fabwire.agent.api import create_app
    from fabwire.logsink import log_in_background

    log_in_background(also=("uvicorn",))  # a stderr nobody reads must not freeze the agent

    server_class = _server_class()
    terminal = Terminal()
    simulators: list[Any] = []
    passing: frozenset[str] = frozenset()
    agent = Agent(state_dir=state_dir, retention_s=retention_s, max_upload_bytes=policy.max_upload_bytes)
    bridge_task: asyncio.Task[None] | None = None
    notify_task: asyncio.Task[None] | None = None
    terminal_task: asyncio.Task[None] | None = None
    show: asyncio.Task[None] | None = None
    advertiser: Advertiser | None = None
    advertising: asyncio.Task[None] | None = None
    try:
        if demo:
            simulators, demo_specs = await asyncio.to_thread(_start_demo, speed)
            passing = frozenset(spec.fixed_id for spec in demo_specs if spec.fixed_id)
            specs = demo_specs + specs
        await agent.start()
        terminal_task = asyncio.create_task(terminal.run(agent))  # subscribed before the devices come
        if notifier is not None:  # subscribed before the devices come: their first states arm it
            notify_task = asyncio.create_task(notifier.run(agent))
        agent.expected_devices = len(specs)
        results = await asyncio.gather(*(agent.add_device(s) for s in specs), return_exceptions=True)
        for spec, result in zip(specs, results, strict=True):
            if isinstance(result, BaseException):
                click.echo(f"fabwire: not monitoring {spec.name}: {result}", err=True)
        if not agent.sessions():
            click.echo("fabwire: no machines to watch: add one with `fabwire devices add NAME ADDRESS --kind KIND` "
                       "and start again (or POST /api/v1/devices), or try `fabwire serve --demo`", err=True)
        opened = asyncio.Event()
        if demo:
            show = asyncio.create_task(_demo_show(agent, opened))
        app = create_app(agent, max_upload_bytes=policy.max_upload_bytes, policy=policy, on_dashboard=opened.set)
        _raise_open_files()
        logging.getLogger("uvicorn.error").addFilter(_Repeats())
        server = server_class(uvicorn.Config(app, log_level="warning", access_log=False, lifespan="off",
                                               ws="websockets-sansio", http=_http_protocol(), log_config=None,
                                               server_header=False, headers=[("server", SERVER)],
                                               **CONNECTION_SETTINGS))
        bound_host, bound_port = sock.getsockname()[:2]

        def announce() -> None:
            shown = f"[{bound_host}]" if ":" in bound_host else bound_host
            sys.stdout.write(f"{ANNOUNCEMENT}http://{shown}:{bound_port}/\n")
            sys.stdout.flush()
            reach = open_at(sock)  # the wildcard is no address a browser can open
            if reach:
                click.echo(f"fabwire: open it at {', '.join(reach)}", err=True)

        server.announce = announce
        if bridge is not None:
            bridge_task = asyncio.create_task(_run_bridge(bridge(agent, dashboard_url(bound_host, bound_port), passing,
                                                                 terminal=terminal), server))
        advertiser = Advertiser(agent, bound_host, bound_port)
        # mDNS announcing probes the network for seconds: the API answers (and says where) meanwhile
        advertising = asyncio.create_task(advertiser.start(), name="advertise-start")
        _freeze_startup_objects()
        await server.serve(sockets=[sock])
        return bool(server.interrupted)
    finally:
        if advertising is not None:
            advertising.cancel()
            with contextlib.suppress(BaseException):
                await advertising
        if advertiser is not None:
            await advertiser.stop()
        for task in (show, bridge_task, notify_task, terminal_task):
            if task is not None:
                task.cancel()
                with contextlib.suppress(BaseException):
                    await task
        try:
            await agent.stop()
        finally:
            if simulators:  # whatever the agent's stop did, the demo's simulators go with it
                from fabwire.demo.runner import stop_all

                await asyncio.to_thread(stop_all, simulators)


def dashboard_url(host: str, port: int) -> str:
    """The dashboard's address as other machines reach it: a wildcard listen address becomes this computer's
    mDNS name (`raspberrypi.local`, as Raspberry Pi OS and most Linux systems announce themselves)."""
    if host in ("0.0.0.0", "::", ""):
        name = socket.gethostname()
        host = name if "." in name else f"{name}.local"
    return f"http://[{host}]:{port}/" if ":" in host else f"http://{host}:{port}/"


FLOODING_MESSAGES = ("Exceeded concurrency limit.", "Invalid HTTP request received.")
"""uvicorn's warnings that a client can cause once per request: logged once a minute, with a count."""
FLOOD_REPORT_S = 60.0


class _Repeats(logging.Filter):
    """Lets a flooding message through once per FLOOD_REPORT_S, saying how many were left out."""

    def __init__(self) -> None:
        super().__init__()
        self._seen: dict[str, tuple[float, int]] = {}

    def filter(self, record: logging.LogRecord) -> bool:
        message = record.getMessage()
        if message not in FLOODING_MESSAGES:
            return True
        now = time.monotonic()
        last, left_out = self._seen.get(message, (-FLOOD_REPORT_S, 0))
        if now - last < FLOOD_REPORT_S:
            self._seen[message] = (last, left_out + 1)
            return False
        if left_out:
            record.msg, record.args = f"{message} ({left_out} more in the last {FLOOD_REPORT_S:g} s)", ()
        self._seen[message] = (now, 0)
        return True


def _raise_open_files() -> None:
    """A desktop's soft limit (1024) is below limit_concurrency: raise it, within the hard limit."""
    import resource

    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    wanted = OPEN_FILES if hard == resource.RLIM_INFINITY else min(OPEN_FILES, hard)
    if soft != resource.RLIM_INFINITY and soft < wanted:
        with contextlib.suppress(ValueError, OSError):
            resource.setrlimit(resource.RLIMIT_NOFILE, (wanted, hard))


def _http_protocol() -> Any:
    """uvicorn's h11 protocol with a deadline for the request head (uvicorn has none of its own: its
    keep-alive timer stops at the first byte of a request)."""
    import h11
    from uvicorn.protocols.http.h11_impl import H11Protocol

    class HeadDeadline(H11Protocol):
        _head_timer: asyncio.TimerHandle | None = None

        def connection_made(self, transport: asyncio.Transport) -> None:  # type: ignore[override]
            super().connection_made(transport)
            self._arm_head_deadline()

        def on_response_complete(self) -> None:
            super().on_response_complete()
            self._arm_head_deadline()

        def connection_lost(self, exc: Exception | None) -> None:
            if self._head_timer is not None:
                self._head_timer.cancel()
            super().connection_lost(exc)

        def send_400_response(self, msg: str) -> None:
            """uvicorn's refusal of a request it cannot read, with the Server header its other answers carry."""
            headers = [(b"content-type", b"text/plain; charset=utf-8"), (b"connection", b"close"),
                       (b"server", SERVER.encode())]
            for event in (h11.Response(status_code=400, headers=headers, reason=b"Bad Request"),
                          h11.Data(data=msg.encode("ascii")), h11.EndOfMessage()):
                self.transport.write(self.conn.send(event) or b"")
            self.transport.close()

        def _arm_head_deadline(self) -> None:
            if self._head_timer is not None:
                self._head_timer.cancel()
            self._head_timer = self.loop.call_later(HEAD_TIMEOUT_S, self._head_deadline)

        def _head_deadline(self) -> None:
            self._head_timer = None
            if self.transport.is_closing() or self.transport.get_protocol() is not self:
                return  # closed, or now a WebSocket
            if self.cycle is not None and not self.cycle.response_complete:
                self._arm_head_deadline()  # the app is answering a request: look again later
                return
            # no request in the app: a head not complete in time, or the rest of a refused body still dripping in
            self.transport.close()

    return HeadDeadline


def _server_class() -> Any:
    import uvicorn

    class Server(uvicorn.Server):
        """SIGINT/SIGTERM end the agent gracefully (uvicorn would re-raise the signal); `interrupted` tells
        SIGINT, which the CLI then reports as interrupted (130), from SIGTERM (exit code 0)."""

        interrupted = False
        announce: Callable[[], None] | None = None
        """Says where the agent listens, once it serves and a SIGTERM ends it gracefully (not before: a service
        manager that stops it as soon as it is announced gets a clean stop)."""

        async def startup(self, sockets: list[socket.socket] | None = None) -> None:
            await super().startup(sockets=sockets)
            if self.started and self.announce is not None:
                self.announce()

        @contextlib.contextmanager
        def capture_signals(self) -> Iterator[None]:
            loop = asyncio.get_running_loop()
            for sig in (signal.SIGINT, signal.SIGTERM):
                loop.add_signal_handler(sig, self._stop, sig)
            try:
                yield
            finally:
                for sig in (signal.SIGINT, signal.SIGTERM):
                    loop.remove_signal_handler(sig)

        def _stop(self, sig: signal.Signals) -> None:
            self.interrupted = self.interrupted or sig == signal.SIGINT
            self.force_exit = self.should_exit
            self.should_exit = True

    return Server


async def _run_bridge(coro: Coroutine[Any, Any, None], server: Any) -> None:
    try:
        await coro
    except FabwireError as exc:
        click.echo(f"fabwire: error: MQTT bridge: {exc}", err=True)
        server.should_exit = True
        raise


DEMO_SHOW_WAIT_S = 30.0
DEMO_LINEUS_SPEED = 1.0
"""The demo's Line-us draws in real time: the logo takes half a minute, long enough to watch the ink arrive."""


async def _demo_show(agent: Agent, opened: asyncio.Event) -> None:
    """What the demo does once its dashboard is first opened, as the README's picture shows: the printer prints
    the sample, the Line-us draws the sample logo, the MMU loads slot 0 and then stops on its (simulated) FINDA
    fault at slot 1. Until a person looks, the machines stay idle for whatever a script sends them."""
    from fabwire.samples import SAMPLE_GCODE, SAMPLE_SVG, sample_path

    await opened.wait()
    async def until(device: str, done: Callable[[dict[str, Any]], bool]) -> None:
        subscription = agent.subscribe(device)
        try:
            async with asyncio.timeout(DEMO_SHOW_WAIT_S):
                if done({"type": "state", "state": agent.state(device)}):
                    return
                async for event in subscription:
                    if done(event):
                        return
        finally:
            subscription.close()

    def idle(event: dict[str, Any]) -> bool:
        return bool(event["type"] == "state" and event["state"]["summary"]["state"] == "idle")

    async def step(device: str, run: Callable[[], Coroutine[Any, Any, Any]]) -> None:
        try:
            await until(device, idle)
            await run()
        except (FabwireError, TimeoutError) as exc:
            click.echo(f"fabwire: demo: {device}: {exc}", err=True)

    async def mmu() -> None:
        finished = asyncio.ensure_future(until(demo_id("mmu"), lambda e: e["type"] == "event"
                                               and e["event"].get("event") == "action-done"))
        await asyncio.sleep(0)  # subscribed before the tool change starts
        await agent.act(demo_id("mmu"), "tool_change", {"slot": 0})
        await finished
        await agent.act(demo_id("mmu"), "tool_change", {"slot": 1})

    await asyncio.gather(
        step(demo_id("xyz"), lambda: agent.start_job(demo_id("xyz"), SAMPLE_GCODE,
                                                     sample_path(SAMPLE_GCODE).read_bytes())),
        step(demo_id("lineus"), lambda: agent.start_job(demo_id("lineus"), SAMPLE_SVG,
                                                        sample_path(SAMPLE_SVG).read_bytes())),
        step(demo_id("mmu"), mmu))


def _start_demo(speed: float) -> tuple[list[Any], list[DeviceSpec]]:
    from fabwire.demo.mmu_show import FAULT
    from fabwire.demo.runner import start_simulators

    args = {"xyz": ["--speed", f"{speed:g}"], "lineus": ["--speed", f"{min(speed, DEMO_LINEUS_SPEED):g}"],
            "mmu": ["--speed", f"{speed:g}", "--fault", FAULT]}
    sims = start_simulators([(kind, args[kind]) for _, kind in DEMO_DEVICES])
    specs = [DeviceSpec(name, kind, sim.url, {"speed": speed, "auto_retries": 0} if kind == "mmu" else {},  # type: ignore[arg-type]
                        fixed_id=demo_id(kind))
             for (name, kind), sim in zip(DEMO_DEVICES, sims, strict=True)]
    return sims, specs
