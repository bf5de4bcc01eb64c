#!/usr/bin/env python3
"""Writes the light maps the scenes use (pure standard library, no PIL).

polka.png: white dots on black, the 2002 paper's Fig. 7 light map.
Run from this folder: python3 make_assets.py
"""
import struct
import zlib


def write_png(path, width, height, pixel):
    rows = bytearray()
    for y in range(height):
        rows.append(0)  # filter: none
        for x in range(width):
            rows.extend(pixel(x, y))
    def chunk(tag, data):
        body = tag + data
        return struct.pack(">I", len(data)) + body + struct.pack(">I", zlib.crc32(body) & 0xFFFFFFFF)
    png = b"\x89PNG\r\n\x1a\n"
    png += chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0))
    png += chunk(b"IDAT", zlib.compress(bytes(rows), 9))
    png += chunk(b"IEND", b"")
    with open(path, "wb") as f:
        f.write(png)


def polka(x, y, size=128, cells=6, radius=0.3):
    cx = (x + 0.5) / size * cells
    cy = (y + 0.5) / size * cells
    dx = cx - int(cx) - 0.5
    dy = cy - int(cy) - 0.5
    inside = dx * dx + dy * dy < radius * radius
    return (255, 255, 255) if inside else (0, 0, 0)


if __name__ == "__main__":
    write_png("polka.png", 128, 128, polka)
