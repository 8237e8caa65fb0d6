"""`fabwire fleet --mqtt URL`: every device the agents on a broker publish, with the agent that owns it."""

from __future__ import annotations

import asyncio
import contextlib
import time
from typing import Any

import click

from fabwire.cli_support import App, FiniteRange, pass_app
from fabwire.errors import InputError, LinkError, visible
from fabwire.mqtt.fleet_view import FleetView
from fabwire.mqtt.options import BrokerURL
from fabwire.mqtt.topics import HEARTBEAT, PING, PREFIX, Broker, parse_broker


async def read_fleet(broker: Broker, *, settle_s: float = 1.0) -> FleetView:
    """Collect the retained fleet topics for `settle_s` seconds after subscribing, and the heartbeats the live
    agents send in answer to a ping (read the result with `rows(time.monotonic())`). LinkError when the broker
    cannot be reached or refuses the login."""
    try:
        import aiomqtt
    except ImportError:
        raise InputError("MQTT support not installed: pip install 'fabwire[mqtt]'") from None

    view = FleetView()
    wrong = await broker.not_a_broker()
    if wrong is not None:
        raise LinkError(wrong)
    try:
        async with aiomqtt.Client(**broker.client_options()) as client:
            for topic in (f"{PREFIX}/agent/+/status", f"{PREFIX}/agent/+/info", f"{PREFIX}/agent/+/{HEARTBEAT}",
                          f"{PREFIX}/device/+/claim/+", f"{PREFIX}/device/+/info", f"{PREFIX}/device/+/state",
                          f"{PREFIX}/device/+/availability"):
                await client.subscribe(topic, qos=1)
            await client.publish(PING, b"fleet", qos=1)

            async def collect() -> None:
                async for message in client.messages:
                    payload = message.payload if isinstance(message.payload, bytes) else b""
                    view.take(message.topic.value, payload, now=time.monotonic(), retained=message.retain)

            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(settle_s):
                    await collect()
    except aiomqtt.MqttError as exc:
        raise LinkError(broker.failure(exc)) from None
    return view


def _cell(value: Any) -> str:
    """A broker's text as a table cell: shown, never obeyed by the terminal."""
    return visible(str(value)).replace("\n", "\\n") if value else ""


def _table(rows: list[dict[str, Any]], agents: dict[str, str]) -> None:
    from rich.table import Table

    from fabwire.console import console

    table = Table(title=f"{len(rows)} device(s), {sum(1 for s in agents.values() if s == 'online')} agent(s) online")
    for column in ("device", "name", "kind", "model", "agent", "availability", "state", "standby"):
        table.add_column(column)
    for row in rows:
        agent = _cell(row["agent"]) or "-"
        if row["agent"] and not row["agent_online"]:
            agent += " (offline)"
        table.add_row(*(_cell(row[key]) for key in ("device", "name", "kind", "model")), agent,
                      _cell(row["availability"]), _cell(row["state"]), _cell(", ".join(row["standby"])))
    console().print(table)  # markup off: broker strings are not markup


@click.command("fleet")
@click.option("--mqtt", "mqtt_url", required=True, envvar="FABWIRE_MQTT", type=BrokerURL(),
              help="The broker the agents publish to (mqtt://host[:port], mqtts:// for TLS).")
@click.option("--mqtt-user", help="MQTT user name.")
@click.option("--mqtt-password", envvar="FABWIRE_MQTT_PASSWORD", help="MQTT password (or FABWIRE_MQTT_PASSWORD).")
@click.option("--mqtt-tls", is_flag=True, help="Connect with TLS.")
@click.option("--wait", type=FiniteRange(min=0.1, max=60), default=1.0, show_default=True,
              help="Seconds to collect what the broker holds.")
@pass_app
def fleet(app: App, mqtt_url: str, mqtt_user: str | None, mqtt_password: str | None, mqtt_tls: bool,
          wait: float) -> None:
    """List every device the fabwire agents on an MQTT broker publish, and the agent that runs each."""
    broker = parse_broker(mqtt_url, username=mqtt_user, password=mqtt_password, tls=mqtt_tls)
    view = asyncio.run(read_fleet(broker, settle_s=wait))
    rows = view.rows(time.monotonic())
    app.output.result({"agents": view.agents, "devices": rows}, lambda: _table(rows, view.agents))
