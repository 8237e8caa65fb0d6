"""The printer firmware's link rules for the MMU3: heartbeat, timeouts, drop-out and retry limits, the registers
it polls and writes, and the firmware versions it accepts (reference §6, `MK3:Firmware/mmu2_protocol_logic.cpp`)."""

from __future__ import annotations

from typing import Literal

from fabwire.mmu import codes

HEARTBEAT = 1.0
LINK_TIMEOUT = 2.0
DROP_OUT_LIMIT = 10
REPLY_LIMIT = 2.0
"""Link timeouts a reply may take from its request to its newline. The firmware restarts its 2 s clock on every byte,
so a device that trickles bytes without ever ending the line would hold it for ever; a real reply is ≤ 14 bytes."""
AUTO_RETRIES = 3
REJECT_LIMIT = 20
"""Our bound on the firmware's resend-on-R loop, so a permanently busy MMU ends in a clear failure."""
IMMEDIATE_RESENDS = 3
"""Re-sends on R go out at once (after a Q0 look-up) this many times, then one per heartbeat."""
RESYNC_GAP = 0.1
"""Seconds of quiet after a garbled reply before draining and asking again (a reply is one burst of ≤14 bytes)."""
RESTART_AFTER = 5
"""Drop-outs in a row, with no good reply between them, after which the handshake starts again from S0."""
SILENT_RESTART = 2
"""Timeouts in a row with no byte at all between them (the MMU is rebooting: it is deaf for ≈4 s): start over."""
POLL_REGISTERS = (0x08, 0x1B, 0x1C, 0x04, 0x1A)
INIT_REGISTERS = ((0x0B, 5), (0x14, 20))
SUPPORTED = frozenset({(3, 0, 2), (3, 0, 3), (3, 0, 4)})
BUSY_CODES = "KELMTUH"
"""Echoed codes that mean 'the MMU is running a command'. The printer firmware leaves out H and then treats the
idle reply `H0 F0` as a protocol error; we include it so a Home does not trigger endless re-handshakes."""


FSensorMode = Literal["auto", "manual"]
# In "auto" mode the host plays the printer's sensor: on while the MMU feeds to it, off once it unloads, retracts
# or feeds to FINDA (so one missed poll cannot leave it stuck on).
AUTO_FSENSOR_ON = frozenset({codes.Progress.FEEDING_TO_FSENSOR, codes.Progress.FEEDING_TO_NOZZLE})
AUTO_FSENSOR_OFF = frozenset({codes.Progress.UNLOADING_TO_FINDA, codes.Progress.RETRACTING_FROM_FINDA,
                              codes.Progress.FEEDING_TO_FINDA})
