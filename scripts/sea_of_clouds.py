#!/usr/bin/env python3
"""Writes the metaballs of scenes/cloud_sea_of_clouds.toml: a sea of clouds
(the 2002 survey's Fig. 7) as a layer of overlapping metaballs spread over
the view from the camera (x = 0, z = 12.5 km) to 50 km beyond it, wider
and with larger balls farther out so that the layer reaches the horizon,
its top rolling in mounds; radii and weights from a fixed seed (so the
file is reproducible), one ball a line (x y z radius q, metres).
Usage: scripts/sea_of_clouds.py [count] > scenes/assets/sea_of_clouds.metaballs"""
import math
import random
import sys

count = int(sys.argv[1]) if len(sys.argv) > 1 else 10000
random.seed(2002)
near, far = 12000.0, -50000.0  # the layer's z extent, m (the camera at z = 12 500)
base = 1200.0                  # the layer's flat base, m


def half_width(z):
    """The layer's half-width at z: the view's, a little more."""
    return 3000.0 + 0.75 * (12500.0 - z)


mounds = []
for _ in range(120):
    # None within 8 km of the camera: the near layer stays low.
    z = random.uniform(far, 4500.0)
    w = half_width(z)
    mounds.append((random.uniform(-w, w), z, random.uniform(1500.0, 4000.0), random.uniform(150.0, 500.0)))


def top(x, z):
    """The layer's top above its base at (x, z): a few hundred metres,
    raised into mounds."""
    h = 250.0
    for mx, mz, w, a in mounds:
        h += a * math.exp(-((x - mx) ** 2 + (z - mz) ** 2) / (w * w))
    return h


print("# x y z radius q (m, m, m, m, density at the centre): scripts/sea_of_clouds.py")
for _ in range(count):
    # Uniform in distance: a far strip is wider, so its balls are sparser
    # there, and larger (its radius grows with the distance).
    z = random.uniform(far, near)
    w = half_width(z)
    x = random.uniform(-w, w)
    t = top(x, z)
    grow = 1.0 + (near - z) / 12000.0
    r = random.uniform(180.0, 420.0) * grow
    y = base + r * 0.4 + random.uniform(0.0, 1.0) * max(t - r * 0.4, 0.0)
    # A larger ball is thinner: the same optical depth through it.
    print(f"{x:.1f} {y:.1f} {z:.1f} {r:.1f} {random.uniform(0.5, 1.0) / grow:.3f}")
