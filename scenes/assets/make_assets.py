#!/usr/bin/env python3
"""Writes the light maps the scenes use (pure standard library, no PIL).

polka.png: white dots on black, the 2002 paper's Fig. 7 light map.
stained.png: coloured panes with dark lead lines, for the stained-glass window.
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


PANES = [(230, 40, 40), (40, 90, 230), (250, 200, 40), (40, 180, 80), (180, 60, 200), (250, 250, 230)]


def stained(x, y, size=96, cells=4, lead=2):
    cell = size // cells
    if x % cell < lead or y % cell < lead:
        return (10, 10, 10)
    i, j = x // cell, y // cell
    # A diamond in each pane, in the next colour.
    u = (x % cell) - cell / 2
    v = (y % cell) - cell / 2
    k = (i * 3 + j * 5) % len(PANES)
    if abs(u) + abs(v) < cell * 0.3:
        k = (k + 2) % len(PANES)
    return PANES[k]


if __name__ == "__main__":
    write_png("polka.png", 128, 128, polka)
    write_png("stained.png", 96, 96, stained)
