"""An MMU3 under the agent: the client's own heartbeat (Q0) keeps its status fresh; events are forwarded as
they happen; commands and the printer-dialog buttons go through `MMU`."""

from __future__ import annotations

import time
from typing import Any

from fabwire.agent.drivers.base import Action, Driver, Identity, Param, summary
from fabwire.agent.opening import open_mmu
from fabwire.errors import LinkClosed
from fabwire.mmu.cli import describe, status_dict
from fabwire.mmu.client import MMU
from fabwire.mmu.errors import describe_error
from fabwire.mmu.host import CommandFinished, HostEvent, LinkFailed, StatusUpdated
from fabwire.mmu.protocol import Cut, Eject, Home, Load, Request, ToolChange, Unload

IDLE_ACTIONS = ("tool_change", "load", "unload", "eject", "cut", "home", "reset")
SLOT = Param("slot", "int", "filament slot 0 to 4", 0, 4)
PRESS_SETTLE_S = 3.0
"""Seconds after a button press in which the same error is taken as the MMU still acting on it (it answers the
press within a heartbeat, 1 s of MMU time): past them, the error's buttons are offered again."""
PARKED = 5


def _position_words(selector: int | None, finda: bool | None) -> str | None:
    if finda:
        return "loaded past FINDA"
    if finda is None:
        return None
    if selector == PARKED:
        return "unloaded (selector parked)"
    return "unloaded" if selector is None else f"unloaded (selector at slot {selector})"


DIALOG_ACTIONS = {"Retry": "retry", "Continue": "continue", "Reset MMU": "reset", "Stop print": "stop"}
"""The error dialog's choices (`fabwire.mmu.errors`) offered as actions; Stop is always offered (the printer can
always stop its print), the dialog's other choices (Unload, Load, Eject, Tune, Disable MMU) are the printer's."""


class MMUDriver(Driver):
    kind = "mmu"
    interval_s = 1.0
    actions = (
        Action("tool_change", "Change to a filament slot (T).", (SLOT,), background=True),
        Action("load", "Load filament from a slot to the FINDA (L).", (SLOT,), background=True),
        Action("unload", "Unload the filament (U).", background=True),
        Action("eject", "Eject the filament of a slot (E).", (SLOT,), background=True),
        Action("cut", "Cut the filament of a slot (K).", (SLOT,), background=True),
        Action("home", "Home the selector and idler (H).", background=True),
        Action("retry", "Answer an error as the printer's Retry does (the Middle button)."),
        Action("continue", "Answer an error as the printer's Continue does (the button its dialog gives Continue: "
               "Middle on most errors, Right on 04501, Left on a TMC warning)."),
        Action("stop", "Answer an error as the printer's Stop does: stop following the command; the MMU keeps its "
               "error, and a dialog whose Stop is the printer's sends no button."),
        Action("reset", "Restart the MMU (X0).", confirm=True),
    )

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self.mmu: MMU | None = None
        self.active_slot: int | None = None
        self._failure: str | None = None
        self._unsubscribe: Any = None
        self._error: int | None = None
        """The error the last poll found (its status value), or None."""
        self._pressed: tuple[str, int, float] | None = None
        """A button pressed on that error (the action, the error's value, when): until the MMU reports anything
        else, or PRESS_SETTLE_S have passed, the error is not offered its buttons (a second Retry would reach an MMU
        already retrying; a retry that fails at once back into the same error is offered them again)."""

    def _client(self) -> MMU:
        if self.mmu is None:
            raise LinkClosed("the MMU is not connected")
        return self.mmu

    async def connect(self) -> Identity:
        self._failure = None
        self.mmu = await open_mmu(self.spec.address, self.spec.options)
        self._unsubscribe = self.mmu.subscribe(self._heard)
        version = await self.mmu.version()
        return Identity("MMU3", None, str(version))

    def _heard(self, event: HostEvent) -> None:
        if isinstance(event, StatusUpdated):
            if self._pressed is not None and (event.status.kind != "E" or event.status.value != self._pressed[1]):
                self._pressed = None  # the MMU has moved on from the error the button was pressed on
            return  # polled into the state each second
        if isinstance(event, LinkFailed):
            self._failure = event.info.explained(detail=event.detail)
        if isinstance(event, CommandFinished) and event.result == 0:
            code, value = event.command[:1], event.command[1:]
            if code in "TL" and value.isdigit():
                self.active_slot = int(value)
            elif code in "UE":
                self.active_slot = None
        self.emit(describe(event)[0])

    async def poll(self) -> tuple[dict[str, Any] | None, dict[str, Any]]:
        mmu = self._client()
        failure = self._failure or mmu._failure
        if failure is not None:
            raise LinkClosed(f"the MMU link failed: {failure}")
        status = await mmu.status()
        busy = mmu.logic.busy
        error = describe_error(status.value) if status.kind == "E" else None
        self._error = status.value if error is not None else None
        if self._pressed is not None and (self._pressed[1] != self._error
                                          or time.monotonic() - self._pressed[2] > PRESS_SETTLE_S):
            self._pressed = None
        if error is not None and self._pressed is not None:
            state, busy, actions = "busy", True, []
            text = f"{self._pressed[0]} pressed on: {error.explained(command=status.command)}"
        elif error is not None:
            state, text = "error", error.explained(command=status.command)
            actions = list(dict.fromkeys([DIALOG_ACTIONS[c.label] for c in error.choices if c.label in DIALOG_ACTIONS]
                                         + ["stop"]))
        elif busy:
            state, text, actions = "busy", f"{status.command}: {status.words}", []
        else:
            state, text, actions = "idle", "idle" + (f" ({status.command} {status.words})" if status.words else ""), \
                list(IDLE_ACTIONS)
        active = self.active_slot if status.finda else None
        return status_dict(status), summary(
            state=state, state_text=text, busy=busy, error=str(error) if error else None,
            error_code=f"0x{status.value:04X}" if error else None, active_slot=active,
            filament_position=_position_words(status.selector, status.finda), selector_slot=status.selector,
            idler_slot=status.idler, finda=status.finda, actions=actions)

    async def close(self) -> None:
        mmu, self.mmu = self.mmu, None
        if mmu is not None:
            if self._unsubscribe is not None:
                self._unsubscribe()
            await mmu.close()

    async def act(self, action: str, params: dict[str, Any]) -> dict[str, Any]:
        mmu = self._client()
        speed = float(self.spec.options.get("speed", 1.0) or 1.0)
        limit = 30.0 + 600.0 / speed
        requests: dict[str, type[Request]] = {"tool_change": ToolChange, "load": Load, "eject": Eject, "cut": Cut}
        if action in requests:
            finished = await mmu.run(requests[action](params["slot"]), timeout=limit)
        elif action == "unload":
            finished = await mmu.run(Unload(0), timeout=limit)
        elif action == "home":
            finished = await mmu.run(Home(0), timeout=limit)
        elif action in ("retry", "continue", "stop"):
            button = mmu.dialog_button(action)
            if button is None:  # the printer's own Stop: nothing reaches the MMU, which keeps showing its error
                mmu.logic.abandon()
            else:
                await mmu.press(button)
                if self._error is not None:
                    self._pressed = (action, self._error, time.monotonic())
            return {"ok": True, "action": action}
        else:
            version = await mmu.reset(timeout=limit)
            return {"ok": True, "action": action, "firmware": str(version)}
        return {"ok": True, "action": action, "command": finished.command, "result": finished.result}
