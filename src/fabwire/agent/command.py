"""`fabwire serve`: the agent with its API and dashboard on one port (and, with --mqtt, the MQTT bridge)."""

from __future__ import annotations

import asyncio
import contextlib
import signal
import socket
import sys
from collections.abc import Coroutine, Iterator
from pathlib import Path
from typing import Any

import click

from fabwire.agent.auth import is_loopback, load_or_create_token
from fabwire.agent.core import KINDS, Agent, DeviceSpec
from fabwire.cli_support import App, FiniteRange, pass_app
from fabwire.errors import FabwireError, InputError
from fabwire.simserve import parse_listen

DEFAULT_PORT = 8765
DEMO_DEVICES = (("printer", "xyz"), ("line-us", "lineus"), ("mmu", "mmu"))
ANNOUNCEMENT = "fabwire agent listening on "


def default_state_dir() -> Path:
    """Where the platform keeps application state (history, uploads, the access token)."""
    import platformdirs

    return Path(platformdirs.user_state_dir("fabwire"))


def configured_devices(path: Path | None) -> list[DeviceSpec]:
    """The named devices of the config file, as specs the agent monitors."""
    from fabwire.config import load_devices

    return [DeviceSpec(d.name, d.kind.name, d.endpoint.url, d.options)  # type: ignore[arg-type]
            for d in load_devices(path).values()]


def parse_device_option(text: str, index: int) -> DeviceSpec:
    """`--device KIND=ADDRESS` or `--device NAME:KIND=ADDRESS`."""
    head, sep, address = text.partition("=")
    name, _, kind = head.rpartition(":")
    if not sep or kind not in KINDS or not address:
        raise InputError(f"--device takes KIND=ADDRESS or NAME:KIND=ADDRESS with KIND one of {', '.join(KINDS)}, "
                         f"not {text!r}")
    return DeviceSpec(name or f"{kind}-{index}", kind, address)


def _bind(host: str, port: int) -> socket.socket:
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    try:
        return socket.create_server((host, port), family=family, reuse_port=False)
    except OSError as exc:
        raise InputError(f"cannot listen on {host}:{port}: {exc.strerror or exc}") from None


def _bridge(url: str | None, user: str | None, password: str | None, tls: bool) -> Any:
    """The MQTT bridge's starter, checked before anything else starts (its module ships with fabwire[mqtt])."""
    if url is None:
        return None
    try:
        from fabwire.mqtt.bridge import run_bridge  # type: ignore[import-not-found,unused-ignore]
    except ImportError:
        raise InputError("MQTT support not installed: pip install 'fabwire[mqtt]'") from None

    def start(agent: Agent) -> Coroutine[Any, Any, None]:
        result: Coroutine[Any, Any, None] = run_bridge(agent, url, username=user, password=password, tls=tls)
        return result

    return start


@click.command("serve")
@click.option("--listen", default=f"127.0.0.1:{DEFAULT_PORT}", show_default=True, metavar="HOST:PORT",
              help="Where the API and dashboard listen; any address but loopback needs the access token.")
@click.option("--device", "devices", multiple=True, metavar="[NAME:]KIND=ADDRESS",
              help="Monitor this device too (repeatable), besides the config file's named devices.")
@click.option("--config", "config", type=click.Path(dir_okay=False, path_type=Path),
              help="Named devices file (default: fabwire's devices.toml).")
@click.option("--state-dir", type=click.Path(file_okay=False, path_type=Path),
              help="History, uploads and the access token (default: the platform's state directory).")
@click.option("--demo", is_flag=True, help="Start the three simulators and monitor them.")
@click.option("--speed", type=FiniteRange(min=0.5), default=30.0, show_default=True,
              help="With --demo: simulated time runs this many times faster.")
@click.option("--retention", type=FiniteRange(min=0.01), default=24.0, show_default=True, metavar="HOURS",
              help="Keep history this long.")
@click.option("--max-upload", type=FiniteRange(min=0.001), default=64.0, show_default=True, metavar="MB",
              help="Largest upload accepted.")
@click.option("--token/--no-token", "token", default=None,
              help="Require the access token (default: only when listening beyond loopback, where it is "
                   "always required).")
@click.option("--mqtt", "mqtt_url", metavar="URL", help="Also publish to an MQTT broker (mqtt://host[:port]).")
@click.option("--mqtt-user", help="MQTT user name.")
@click.option("--mqtt-password", help="MQTT password (or FABWIRE_MQTT_PASSWORD).", envvar="FABWIRE_MQTT_PASSWORD")
@click.option("--mqtt-tls", is_flag=True, help="Connect to the broker with TLS.")
@pass_app
def serve(app: App, listen: str, devices: tuple[str, ...], config: Path | None, state_dir: Path | None,
          demo: bool, speed: float, retention: float, max_upload: float, token: bool | None,
          mqtt_url: str | None, mqtt_user: str | None, mqtt_password: str | None, mqtt_tls: bool) -> None:
    """Watch a bench of machines: a live dashboard, an HTTP API with history and jobs, one agent.

    Open the printed address in a browser. The API is described at /api/v1/openapi.json.
    """
    address = parse_listen(listen, DEFAULT_PORT)
    local = is_loopback(address.host)
    if token is False and not local:
        raise InputError(f"refusing to listen on {address.host} without an access token: anyone on the network "
                         "could run the machines (leave out --no-token, or listen on 127.0.0.1)")
    bridge = _bridge(mqtt_url, mqtt_user, mqtt_password, mqtt_tls)
    specs = [parse_device_option(text, i) for i, text in enumerate(devices, 1)]
    if not demo:
        specs = configured_devices(config) + specs
    directory = state_dir or default_state_dir()
    sock = _bind(address.host, address.port)  # a bad address fails before a token is made for it
    try:
        secret = None
        if token or not local:
            secret, created = load_or_create_token(directory)
            if created:
                click.echo(f"access token (shown once; kept in {directory}): {secret}", err=True)
            else:
                click.echo(f"access token: the one in {directory}", err=True)
        interrupted = _run(_serve(sock, specs, directory, demo, speed, retention * 3600.0,
                                  int(max_upload * 1024 * 1024), secret, bridge))
    finally:
        sock.close()
    if interrupted:
        raise KeyboardInterrupt  # after the clean shutdown: the CLI's "interrupted" exit code


def _run(main: Coroutine[Any, Any, bool]) -> bool:
    """On uvloop where it is installed: a bench of machines costs a fifth less CPU per poll."""
    try:
        import uvloop
    except ImportError:
        return asyncio.run(main)
    return uvloop.run(main)


async def _serve(sock: socket.socket, specs: list[DeviceSpec], state_dir: Path, demo: bool, speed: float,
                 retention_s: float, max_upload: int, secret: str | None, bridge: Any) -> bool:
    """Serve until a signal; True when it was SIGINT (Ctrl-C), False for SIGTERM (a service manager's stop)."""
    import uvicorn

    from fabwire.agent.advertise import Advertiser
    from fabwire.agent.api import create_app
    from fabwire.agent.auth import TokenGuard
    from fabwire.logsink import log_in_background

    log_in_background(also=("uvicorn",))  # a stderr nobody reads must not freeze the agent

    server_class = _server_class()
    simulators: list[Any] = []
    agent = Agent(state_dir=state_dir, retention_s=retention_s, max_upload_bytes=max_upload)
    bridge_task: asyncio.Task[None] | None = None
    advertiser: Advertiser | None = None
    try:
        if demo:
            simulators, demo_specs = await asyncio.to_thread(_start_demo, speed)
            specs = demo_specs + specs
        await agent.start()
        results = await asyncio.gather(*(agent.add_device(s) for s in specs), return_exceptions=True)
        for spec, result in zip(specs, results, strict=True):
            if isinstance(result, BaseException):
                click.echo(f"fabwire: not monitoring {spec.name}: {result}", err=True)
        app: Any = create_app(agent, max_upload_bytes=max_upload)
        if secret is not None:
            app = TokenGuard(app, secret)
        server = server_class(uvicorn.Config(app, log_level="warning", access_log=False, lifespan="off",
                                               ws="websockets-sansio", log_config=None))
        bound_host, bound_port = sock.getsockname()[:2]
        shown = f"[{bound_host}]" if ":" in bound_host else bound_host
        sys.stdout.write(f"{ANNOUNCEMENT}http://{shown}:{bound_port}/\n")
        sys.stdout.flush()
        if bridge is not None:
            bridge_task = asyncio.create_task(_run_bridge(bridge(agent), server))
        advertiser = Advertiser(agent, bound_host, bound_port)
        await advertiser.start()
        await server.serve(sockets=[sock])
        return bool(server.interrupted)
    finally:
        if advertiser is not None:
            await advertiser.stop()
        if bridge_task is not None:
            bridge_task.cancel()
            with contextlib.suppress(BaseException):
                await bridge_task
        await agent.stop()
        if simulators:
            from fabwire.demo.runner import stop_all

            await asyncio.to_thread(stop_all, simulators)


def _server_class() -> Any:
    import uvicorn

    class Server(uvicorn.Server):
        """SIGINT/SIGTERM end the agent gracefully (uvicorn would re-raise the signal); `interrupted` tells
        SIGINT, which the CLI then reports as interrupted (130), from SIGTERM (exit code 0)."""

        interrupted = False

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


def _start_demo(speed: float) -> tuple[list[Any], list[DeviceSpec]]:
    from fabwire.demo.mmu_show import FAULT
    from fabwire.demo.runner import start_simulators

    args = {"xyz": ["--speed", f"{speed:g}"], "lineus": ["--speed", f"{speed:g}"],
            "mmu": ["--speed", f"{speed:g}", "--fault", FAULT]}
    sims = start_simulators([(kind, args[kind]) for _, kind in DEMO_DEVICES])
    specs = [DeviceSpec(name, kind, sim.url, {"speed": speed, "auto_retries": 0} if kind == "mmu" else {},  # type: ignore[arg-type]
                        fixed_id=f"{kind}-demo")
             for (name, kind), sim in zip(DEMO_DEVICES, sims, strict=True)]
    return sims, specs
