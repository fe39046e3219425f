#!/usr/bin/env python3
"""Writes tests/data/protocol_vectors.txt: the link's test vectors (docs/protocol.md).

A third, independent implementation of the framing and CRC (CRC-16/CCITT-FALSE, poly 0x1021,
init 0xFFFF), so the C and Rust sides are checked against something neither of them produced.
Run it only to change the vectors on purpose: python3 tests/data/gen_protocol_vectors.py
"""
import os
import struct

START = 0xA5


def crc16(data):
    crc = 0xFFFF
    for b in data:
        crc ^= b << 8
        for _ in range(8):
            crc = ((crc << 1) ^ 0x1021) & 0xFFFF if crc & 0x8000 else (crc << 1) & 0xFFFF
    return crc


assert crc16(b"123456789") == 0x29B1


def frame(mid, seq, payload):
    body = bytes([len(payload), mid, seq]) + payload
    return bytes([START]) + body + struct.pack("<H", crc16(body))


# (name, id, seq, [(field, struct code, value)])
CONFIG = [("servo_min_us", "H"), ("servo_center_us", "H"), ("servo_max_us", "H"), ("esc_min_us", "H"),
          ("esc_neutral_us", "H"), ("esc_max_us", "H"), ("failsafe_ms", "H")]
TELEMETRY = [("state", "B"), ("flags", "B"), ("last_rx_seq", "B"), ("drive_seq", "B"), ("servo_us", "H"),
             ("esc_us", "H"), ("crc_errors", "H"), ("framing_errors", "H"), ("overruns", "H"),
             ("failsafe_trips", "H"), ("lost_frames", "H"), ("rx_frames", "I"), ("uptime_ms", "I")]


def cfg(flags, vals):
    return [("flags", "B", flags)] + [(n, c, v) for (n, c), v in zip(CONFIG, vals)]


OK = [
    ("hello_v1", 0x01, 0, [("protocol_version", "B", 1)]),
    ("drive_zero", 0x02, 1, [("steer", "h", 0), ("throttle", "h", 0)]),
    ("drive_full_right_forward", 0x02, 2, [("steer", "h", 1000), ("throttle", "h", 1000)]),
    ("drive_full_left_reverse", 0x02, 3, [("steer", "h", -1000), ("throttle", "h", -1000)]),
    ("drive_seq_wraps", 0x02, 255, [("steer", "h", -123), ("throttle", "h", 456)]),
    # START bytes inside the payload must not confuse the receiver
    ("drive_start_bytes_in_payload", 0x02, 0xA5, [("steer", "h", 0x00A5), ("throttle", "h", -23131)]),
    ("arm", 0x03, 4, []),
    ("disarm", 0x04, 5, []),
    ("ping", 0x05, 6, []),
    ("config_set_persist", 0x06, 7, cfg(1, [1100, 1480, 1900, 1200, 1500, 1800, 250])),
    ("config_get", 0x07, 8, []),
    ("hello_ack_ok", 0x81, 0, [("re_seq", "B", 0), ("status", "B", 0), ("protocol_version", "B", 1),
                               ("fw_major", "B", 1), ("fw_minor", "B", 0), ("fw_patch", "B", 0)]),
    ("hello_ack_mismatch", 0x81, 1, [("re_seq", "B", 200), ("status", "B", 4), ("protocol_version", "B", 1),
                                     ("fw_major", "B", 1), ("fw_minor", "B", 2), ("fw_patch", "B", 3)]),
    ("status_not_armed", 0x82, 2, [("re_id", "B", 2), ("re_seq", "B", 9), ("status", "B", 2)]),
    ("telemetry_armed", 0x83, 3, list(zip([n for n, _ in TELEMETRY], [c for _, c in TELEMETRY],
                                          [1, 0x18, 77, 76, 1734, 1366, 3, 5, 1, 2, 9, 123456, 0x89ABCDEF]))),
    ("telemetry_failsafe_ping", 0x83, 4, list(zip([n for n, _ in TELEMETRY], [c for _, c in TELEMETRY],
                                                  [2, 0x0B, 0, 250, 1500, 1500, 65535, 0, 0, 1, 0, 1, 250]))),
    ("config_defaults", 0x84, 5, cfg(0, [1000, 1500, 2000, 1000, 1500, 2000, 250])),
]


def main():
    out = [
        "# rccar link test vectors (docs/protocol.md), read by firmware/tests/test_protocol.c and",
        "# src/link/protocol.rs. Written by tests/data/gen_protocol_vectors.py; do not edit by hand.",
        "#",
        "# ok  NAME ID SEQ FRAME_HEX FIELD=VALUE...   a valid frame and its decoded fields",
        "# bad NAME CRC_ERRORS FRAMING_ERRORS FRAME_HEX  bytes a receiver must reject, with the counts",
    ]
    frames = {}
    for name, mid, seq, fields in OK:
        payload = b"".join(struct.pack("<" + c, v) for _, c, v in fields)
        f = frame(mid, seq, payload)
        frames[name] = f
        kv = " ".join(f"{n}={v}" for n, _, v in fields)
        out.append(f"ok {name} 0x{mid:02X} {seq} {f.hex().upper()} {kv}".rstrip())
    d = bytearray(frames["drive_full_right_forward"])
    d[-1] ^= 0x01
    out.append(f"bad drive_crc_flipped 1 0 {bytes(d).hex().upper()}")
    d = bytearray(frames["drive_zero"])
    d[5] ^= 0x80  # payload bit: the CRC catches it
    out.append(f"bad drive_payload_bit 1 0 {bytes(d).hex().upper()}")
    out.append(f"bad len_too_long 0 1 {frame(0x02, 1, bytes(33)).hex().upper()}")
    body = bytes([3, 0x02, 1, 0, 0, 0])
    out.append(f"bad drive_len_mismatch 0 1 {(bytes([START]) + body + struct.pack('<H', crc16(body))).hex().upper()}")
    out.append(f"bad garbage_only 0 1 0102030405")
    path = os.path.join(os.path.dirname(os.path.abspath(__file__)), "protocol_vectors.txt")
    with open(path, "w") as fh:
        fh.write("\n".join(out) + "\n")


if __name__ == "__main__":
    main()
