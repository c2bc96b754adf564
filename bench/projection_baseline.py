#!/usr/bin/env python3
"""Fold-free projection atlases without any networks: the baseline behind `[warm_start]`.

Each face goes to the chart of the coordinate axis (±x, ±y, ±z) its normal faces most; a chart is
the orthographic projection of its faces onto the plane orthogonal to that axis, scaled uniformly
into its tile of a 3×2 atlas. `--smooth R` first averages the face normals over a grid of cells of
side R (times the object's extent) and their neighbours, which makes the charts less ragged.
Score the result the paper's way with `nuvo eval OUT`.

    python3 bench/projection_baseline.py assets/stanford-bunny.obj /tmp/cube.obj
    python3 bench/projection_baseline.py assets/stanford-bunny.obj /tmp/cube_s.obj --smooth 0.03
    cargo run --release --bin nuvo -- eval /tmp/cube.obj

Needs only numpy.
"""
import argparse

import numpy as np

from objio import read_obj


def smoothed(normals, centroids, radius, rounds=2):
    """Sums each face's normal with those in its grid cell and the 26 neighbouring cells."""
    cells = int(np.ceil(1.0 / radius)) + 2
    key = np.floor((centroids + 0.5) / radius).astype(np.int64) + 1
    flat = (key[:, 0] * cells + key[:, 1]) * cells + key[:, 2]
    out = normals
    for _ in range(rounds):
        grid = np.zeros((cells**3, 3))
        np.add.at(grid, flat, out)
        grid = grid.reshape(cells, cells, cells, 3)
        total = np.zeros_like(grid)
        for dx in (-1, 0, 1):
            for dy in (-1, 0, 1):
                for dz in (-1, 0, 1):
                    total += np.roll(grid, (dx, dy, dz), axis=(0, 1, 2))
        out = total.reshape(-1, 3)[flat]
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("mesh")
    ap.add_argument("out")
    ap.add_argument("--smooth", type=float, default=0.0, help="normal smoothing cell size (0: none)")
    args = ap.parse_args()

    verts, faces = read_obj(args.mesh)
    lo, hi = verts.min(0), verts.max(0)
    unit = (verts - (lo + hi) / 2) / (hi - lo).max()  # the model frame: inside [-0.5, 0.5]^3
    a, b, c = unit[faces[:, 0]], unit[faces[:, 1]], unit[faces[:, 2]]
    normals = np.cross(b - a, c - a)
    if args.smooth > 0:
        normals = smoothed(normals, (a + b + c) / 3, args.smooth)
    axis = np.abs(normals).argmax(1)
    positive = normals[np.arange(len(faces)), axis] > 0
    chart = axis * 2 + positive

    with open(args.out, "w") as out:
        out.write(f"# projection baseline of {args.mesh}: {len(faces)} faces, 6 charts\n")
        for k, (face, ch) in enumerate(zip(faces, chart)):
            ax = ch // 2
            u_axis, v_axis = [i for i in range(3) if i != ax]
            tile_u, tile_v = ch % 3, ch // 3
            for vtx in face:
                u, v = unit[vtx, u_axis] + 0.5, unit[vtx, v_axis] + 0.5
                if ch % 2 == 0:  # mirror the negative side so every chart keeps its orientation
                    u = 1.0 - u
                out.write("v %.6f %.6f %.6f\n" % tuple(verts[vtx]))
                out.write("vt %.6f %.6f\n" % ((tile_u + 0.05 + 0.9 * u) / 3, (tile_v + 0.05 + 0.9 * v) / 3))
            i = 3 * k + 1
            out.write(f"f {i}/{i} {i + 1}/{i + 1} {i + 2}/{i + 2}\n")


if __name__ == "__main__":
    main()
