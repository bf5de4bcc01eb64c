#!/usr/bin/env python3
"""Writes the OpenVDB files the project ships, with OpenVDB's own Python
module (Debian: `apt-get install python3-openvdb`, then run it with
/usr/bin/python3):

- scenes/cloud_grid.vdb: scenes/cloud_grid.vol's 48 x 24 x 48 values as a
  float grid named "density", every voxel active (zeros too), so its
  active bounding box is the .vol file's cells and cloud_vdb.toml renders
  exactly as cloud_grid.toml;
- tests/data/*.vdb: the reader's test files (tests/volumes.rs,
  `vdb_grids_load_as_their_voxels` and `bad_vdb_files_name_the_field`).

Deterministic: run it again to get the same grids (the files differ only
in the UUID OpenVDB writes into each)."""

import os
import struct
import sys

import pyopenvdb as vdb

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")


def cloud():
    data = open(os.path.join(ROOT, "scenes", "cloud_grid.vol"), "rb").read()
    nx, ny, nz, channels = struct.unpack("<4i", data[8:24])
    assert data[:4] == b"VOL\x03" and channels == 1
    values = struct.unpack("<%df" % (nx * ny * nz), data[48:])
    grid = vdb.FloatGrid()
    grid.name = "density"
    acc = grid.getAccessor()
    for k in range(nz):
        for j in range(ny):
            for i in range(nx):
                acc.setValueOn((i, j, k), values[(k * ny + j) * nx + i])
    vdb.write(os.path.join(ROOT, "scenes", "cloud_grid.vdb"), grids=[grid])


def tests():
    out = os.path.join(ROOT, "tests", "data")
    # 6 x 4 x 3 voxels from (10, -2, 5), each value telling its place, and
    # a second grid beside it.
    small = vdb.FloatGrid()
    small.name = "density"
    acc = small.getAccessor()
    for i in range(6):
        for j in range(4):
            for k in range(3):
                acc.setValueOn((10 + i, -2 + j, 5 + k), 1.0 + i + 10 * j + 100 * k)
    small.transform = vdb.createLinearTransform(voxelSize=0.5)
    other = vdb.FloatGrid()
    other.name = "temperature"
    other.getAccessor().setValueOn((0, 0, 0), 3.0)
    vdb.write(os.path.join(out, "small.vdb"), grids=[small, other])
    # Two 8^3 tiles (a fill over whole leaf nodes) and one voxel.
    tiles = vdb.FloatGrid()
    tiles.name = "density"
    tiles.fill((0, 0, 0), (15, 7, 7), 0.25)
    tiles.getAccessor().setValueOn((3, 3, 3), 2.0)
    vdb.write(os.path.join(out, "tiles.vdb"), grids=[tiles])
    # Four voxels saved as half floats (refused: see host/src/volumes/grid.rs).
    half = vdb.FloatGrid()
    half.name = "density"
    for i in range(4):
        half.getAccessor().setValueOn((i, 0, 0), 0.5 * i)
    half.saveFloatAsHalf = True
    vdb.write(os.path.join(out, "half.vdb"), grids=[half])
    # 256^3 voxels (eight 128^3 tiles): over the reader's 2^23 cells.
    big = vdb.FloatGrid()
    big.name = "density"
    big.fill((0, 0, 0), (255, 255, 255), 1.0)
    vdb.write(os.path.join(out, "big.vdb"), grids=[big])
    vector = vdb.Vec3SGrid()
    vector.name = "velocity"
    vector.getAccessor().setValueOn((0, 0, 0), (1.0, 2.0, 3.0))
    vdb.write(os.path.join(out, "vector.vdb"), grids=[vector])
    negative = vdb.FloatGrid()
    negative.name = "density"
    negative.getAccessor().setValueOn((1, 2, 3), -0.5)
    vdb.write(os.path.join(out, "negative.vdb"), grids=[negative])


if __name__ == "__main__":
    cloud()
    tests()
    sys.exit(0)
