"""Modbus TCP framing for the benchmarks' minimal slaves: cut requests, frame answers."""

from __future__ import annotations

import struct


def split_requests(buffer: bytes) -> tuple[list[bytes], bytes]:
    """The whole request frames at the start of ``buffer``, and the bytes after them.

    A frame is the MBAP header (transaction id, protocol, length, unit id) and its PDU.
    The minimal slaves only take requests of at least 12 bytes (function code, address,
    count), so fewer bytes wait for more.
    """
    frames: list[bytes] = []
    while len(buffer) >= 12:
        end = 6 + int.from_bytes(buffer[4:6], "big")
        if len(buffer) < end:
            break
        frames.append(buffer[:end])
        buffer = buffer[end:]
    return frames, buffer


def answer_frame(request: bytes, pdu: bytes) -> bytes:
    """The frame answering ``request`` with ``pdu``: its transaction and unit id."""
    tid, _protocol, _length, unit = struct.unpack(">HHHB", request[:7])
    return struct.pack(">HHHB", tid, 0, len(pdu) + 1, unit) + pdu
