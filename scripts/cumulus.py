#!/usr/bin/env python3
"""Writes the metaballs of scenes/cloud_cumulus.toml and
cloud_cumulus_splat.toml: a cumulus as balls inside a half-ellipsoid with a
flat base, radii and weights drawn from a fixed seed (so the file is
reproducible), one ball a line (x y z radius q, metres).
Usage: scripts/cumulus.py > scenes/assets/cumulus.metaballs"""
import random

random.seed(2000)
centre = (0.0, 1500.0, -4000.0)  # middle of the cloud's flat base, m
half = (650.0, 600.0, 500.0)     # half-widths of the ellipsoid, m
balls = []
while len(balls) < 60:
    x, y, z = (random.uniform(-1, 1) for _ in range(3))
    y = abs(y)
    if x * x + y * y + z * z > 1.0:
        continue
    r = random.uniform(140.0, 320.0) * (1.0 - 0.35 * y)
    c = (centre[0] + x * half[0], centre[1] + 120.0 + y * half[1], centre[2] + z * half[2])
    balls.append((c, r, random.uniform(0.7, 1.0)))
print("# x y z radius q (m, m, m, m, density at the centre): scripts/cumulus.py")
for c, r, q in balls:
    print(f"{c[0]:.1f} {c[1]:.1f} {c[2]:.1f} {r:.1f} {q:.2f}")
