"""uDMX (anyma.ch, VID 0x16C0 PID 0x05DC) over pyusb: vendor control transfers.

``cmd_SetChannelRange`` (bRequest 2) writes ``wValue`` slots starting at 0-based slot
``wIndex``, levels in the data stage. See docs/protocols/udmx.md.
"""

from __future__ import annotations

from drivers.lights.dmx import DmxLight
from drivers.transports.usb_device import VENDOR_OUT, control_out

UDMX_VID, UDMX_PID = 0x16C0, 0x05DC
UDMX_PRODUCT = "uDMX"  # the id is V-USB's shared one: the product string tells a uDMX apart
CMD_SET_SINGLE_CHANNEL = 1
CMD_SET_CHANNEL_RANGE = 2


class UDmx(DmxLight):
    driver_name = "udmx"

    def _send(self, slots: bytes) -> None:
        control_out(self.transport, VENDOR_OUT, CMD_SET_CHANNEL_RANGE, len(slots), 0, slots)
