"""Velleman K8062 / VM116 USB DMX interface over HID: a frame as a train of 8-byte reports.

Report types (first byte), as the OLA usbdmx plugin documents them:
``4`` starts a frame: [4, leading zeros + 1 (start code), 6 slots];
``5`` continues after zeros: [5, zeros, 6 slots]; ``2`` continues: [2, 7 slots];
``3`` sends one trailing slot: [3, slot, 0...]. See docs/protocols/velleman-k8062.md.

The widget puts a frame on the DMX line only when the next frame begins (OLA keeps streaming
frames for this reason), so every change is sent twice: the copy releases the real frame, and
whatever comes next releases the copy, which holds the same levels.
"""

from __future__ import annotations

from drivers.lights.dmx import DmxLight

VELLEMAN_VID, K8062_PID = 0x10CF, 0x8062
REPORT_SIZE = 8
BREAK_MSG, INTERMEDIATE_MSG, SINGLE_SLOT_MSG, COMPRESSED_MSG = 4, 2, 3, 5
MAX_LEADING_ZEROS = 100  # the standard firmware misbehaves beyond this (OLA)
FRAMES_PER_CHANGE = 2  # see the module docstring


def leading_zeros(data: bytes) -> int:
    count, rest = 0, REPORT_SIZE - 2
    while count < MAX_LEADING_ZEROS and count + rest < len(data) and data[count] == 0:
        count += 1
    return count


def frame_reports(slots: bytes) -> list[bytes]:
    """The 8-byte reports that send ``slots`` (DMX slots 1..n, no start code)."""
    reports: list[bytes] = []
    size = len(slots)

    def report(*parts: bytes) -> None:
        body = b"".join(parts)
        reports.append(body + bytes(REPORT_SIZE - len(body)))

    zeros = leading_zeros(slots)
    report(bytes([BREAK_MSG, zeros + 1]), slots[zeros : zeros + 6])
    i = zeros + 6
    while i < size - (REPORT_SIZE - 1):
        zeros = leading_zeros(slots[i:])
        if zeros:
            report(bytes([COMPRESSED_MSG, zeros]), slots[i + zeros : i + zeros + 6])
            i += zeros + 6
        else:
            report(bytes([INTERMEDIATE_MSG]), slots[i : i + 7])
            i += 7
    for value in slots[i:]:
        report(bytes([SINGLE_SLOT_MSG, value]))
    return reports


class VellemanK8062(DmxLight):
    driver_name = "velleman-k8062"

    def _send(self, slots: bytes) -> None:
        for chunk in frame_reports(slots) * FRAMES_PER_CHANGE:
            self.transport.write(chunk)
