#!/usr/bin/env python3
"""Writes a shaded-relief image of an SRTM .hgt tile (sea blue, land lit from the north-west),
scaled up by FACTOR: imagery much deeper than the coarse world topography, for measuring how
imagery that is deeper than the terrain streams. Needs Pillow only.

    python3 tools/hillshade.py N57E011.hgt OUT.png [FACTOR]
"""
import math
import struct
import sys

from PIL import Image


def main():
    raw = open(sys.argv[1], "rb").read()
    n = int(math.isqrt(len(raw) // 2))
    if n * n * 2 != len(raw):
        sys.exit(f"{sys.argv[1]}: not a square grid of 16-bit samples")
    factor = int(sys.argv[3]) if len(sys.argv) > 3 else 2
    h = [max(v, 0) if v > -1000 else 0 for v in struct.unpack(f">{n * n}h", raw)]
    spacing = 1.0 / (n - 1) * 111_000.0  # metres between samples (north-south)
    az, alt = math.radians(315.0), math.radians(45.0)
    out = bytearray(n * n * 3)
    for y in range(n):
        row = y * n
        for x in range(n):
            v = h[row + x]
            i = row * 3 + x * 3
            if v <= 0:
                out[i:i + 3] = b"\x28\x46\x78"
                continue
            west = h[row + max(x - 1, 0)]
            east = h[row + min(x + 1, n - 1)]
            north = h[max(y - 1, 0) * n + x]
            south = h[min(y + 1, n - 1) * n + x]
            dx = (east - west) / (2 * spacing * 0.55)  # 57 N: a degree of longitude is shorter
            dy = (north - south) / (2 * spacing)
            slope = math.atan(math.hypot(dx, dy))
            aspect = math.atan2(-dx, dy)
            shade = math.sin(alt) * math.cos(slope) + math.cos(alt) * math.sin(slope) * math.cos(az - aspect)
            shade = min(max(shade, 0.0), 1.0)
            out[i] = int(120 + 100 * shade)
            out[i + 1] = int(140 + 90 * shade)
            out[i + 2] = int(90 + 60 * shade)
    img = Image.frombytes("RGB", (n, n), bytes(out))
    img.resize((n * factor, n * factor), Image.BICUBIC).save(sys.argv[2])


if __name__ == "__main__":
    main()
