#!/usr/bin/env python3
"""Writes scenes/cloud_grid.vol: a 48 x 24 x 48 Mitsuba .vol density grid
(version 3, float32, one channel; x fastest, then y, then z) of a lumpy
cloud: a flattened ellipsoid whose edge is pushed in and out by a few
sinusoids, densities in [0, 1] falling smoothly to 0 at the edge.
Deterministic (no random numbers): run it again to get the same bytes."""

import math
import struct
import sys

NX, NY, NZ = 48, 24, 48


def density(x, y, z):
    # Cell-centre coordinates in [-1, 1] on each axis.
    r = math.sqrt(x * x + (y * 1.6 + 0.25) ** 2 + z * z)
    bumps = (0.12 * math.sin(5.0 * x + 1.0) * math.cos(4.0 * z)
             + 0.08 * math.sin(9.0 * z - 2.0 * x)
             + 0.10 * max(0.0, y + 0.2) * math.cos(7.0 * x + 3.0 * z))
    edge = 0.85 + bumps
    if r >= edge or y < -0.45:
        return 0.0
    t = 1.0 - (r / edge) ** 2
    return min(1.0, 1.5 * t * t)


def main(path):
    values = []
    for k in range(NZ):
        for j in range(NY):
            for i in range(NX):
                x = 2.0 * (i + 0.5) / NX - 1.0
                y = 2.0 * (j + 0.5) / NY - 1.0
                z = 2.0 * (k + 0.5) / NZ - 1.0
                values.append(density(x, y, z))
    with open(path, "wb") as f:
        f.write(b"VOL" + bytes([3]))
        f.write(struct.pack("<iiiii", 1, NX, NY, NZ, 1))
        f.write(struct.pack("<6f", 0.0, 0.0, 0.0, 1.0, 1.0, 1.0))
        f.write(struct.pack("<%df" % len(values), *values))


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "scenes/cloud_grid.vol")
