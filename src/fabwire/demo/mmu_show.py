"""The MMU3 part: handshake, tool changes in words, an injected FINDA fault and its recovery by Retry."""

from __future__ import annotations

import asyncio
from collections.abc import Callable

from rich.markup import escape

from fabwire.demo.context import DemoContext
from fabwire.devices import MMU as MMU_KIND
from fabwire.errors import LinkTimeout
from fabwire.mmu.cli import describe, status_line
from fabwire.mmu.client import MMU
from fabwire.mmu.errors import MMUError
from fabwire.mmu.host import ButtonPushed, CommandFinished, ErrorRaised, HostEvent, LinkLost, ProgressChanged
from fabwire.transport import open_transport

FAULT = "finda-didnt-trigger@1:1"
"""Lets the first feed to FINDA (T0) pass, then fires once: on the T1 tool change."""
SLOTS = (0, 1, 2)


async def showcase(ctx: DemoContext, url: str) -> None:
    ctx.heading("Prusa MMU3 (MMU protocol over TCP)")
    limit = 30.0 + 600.0 / ctx.speed
    transport = await open_transport(url, MMU_KIND)
    try:
        with ctx.summary.step("mmu", "boot + handshake") as step:
            mmu = MMU(transport, time_scale=ctx.speed, auto_retries=0, connect_timeout=max(5.0, 30.0 / ctx.speed))
            await mmu.connect()
            firmware = await mmu.version()
            step.detail = f"firmware {firmware}"
            ctx.say(f"link up: MMU firmware {firmware}; {status_line(await mmu.status())}")
        try:
            for slot in SLOTS:
                await _tool_change(ctx, mmu, slot, limit)
        finally:
            await mmu.close()
    finally:
        await transport.close()


def _show(ctx: DemoContext) -> Callable[[HostEvent], None]:
    def show(event: HostEvent) -> None:
        if isinstance(event, ProgressChanged | ErrorRaised | ButtonPushed | LinkLost):
            ctx.say("  " + describe(event)[1])

    return show


async def _tool_change(ctx: DemoContext, mmu: MMU, slot: int, limit: float) -> None:
    with ctx.summary.step("mmu", f"tool change T{slot}") as step:
        try:
            await mmu.tool_change(slot, on_event=_show(ctx), timeout=limit)
            step.detail = "finished"
        except MMUError as exc:
            ctx.say(f"  [yellow]the MMU stopped[/yellow]: {escape(str(exc))}", markup=True)
            ctx.say("  pressing Retry (the MMU's middle button) from the host")
            finished = asyncio.Event()
            show = _show(ctx)

            def watch(event: HostEvent) -> None:
                show(event)
                if isinstance(event, CommandFinished) and event.command == f"T{slot}":
                    finished.set()

            unsubscribe = mmu.subscribe(watch)
            try:
                await mmu.press("middle")  # Retry: the Middle button on every dialog that offers it
                try:
                    async with asyncio.timeout(limit):
                        await finished.wait()
                except TimeoutError:
                    raise LinkTimeout(f"T{slot} did not finish within {limit:g} s after Retry") from None
            finally:
                unsubscribe()
            step.detail = f"recovered from {exc.info} by Retry"
        ctx.say(f"T{slot} finished: {status_line(await mmu.status())}")
