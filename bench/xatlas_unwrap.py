#!/usr/bin/env python3
"""Unwrap OBJ meshes with xatlas at its default options: the baseline of bench/suite.py.

    bench/.venv/bin/python bench/xatlas_unwrap.py MESH.obj [MESH.obj ...] -o DIR

For each input mesh (OBJ `v` and `f` lines only; polygons fan-triangulated from their first
corner; 1-based and negative indices) this runs xatlas with its default chart and pack options
(exactly what `xatlas.parametrize(vertices, faces)` does: `Atlas()`, `add_mesh`, `generate()`
with default `ChartOptions()`/`PackOptions()`, `get_mesh(0)`; the explicit form is used only to
read xatlas' chart count) and writes

- `DIR/<name>/atlas.obj`: the input's `v` lines verbatim and in input order, one `vt` per xatlas
  output vertex, and the input's faces in input order as `f v/vt v/vt v/vt` (so the 3-D mesh is
  exactly the input, triangulated; only the UVs are new). `nuvo eval` scores it.
- `DIR/<name>/xatlas.json`: `seconds` (wall time of the xatlas call alone), `seconds_with_io`
  (reading the OBJ + xatlas + writing atlas.obj), `charts_reported_by_xatlas`, `vertices`,
  `faces`, atlas size and utilisation, versions. A mesh that fails gets `"error"` there instead
  and the script goes on with the next one (exit code 1 if any failed).

`<name>` is the file name without `.obj` (`--name` overrides it for a single input).
"""
import argparse
import json
import os
import sys
import time
import traceback

import numpy as np
import xatlas

from benchio import write_json


def read_obj(path):
    """The `v` and `f` lines of an OBJ.

    Returns (vertex_tokens, positions, triangles): the coordinate text of every `v` line as
    written (first three numbers), the positions as float64 (V x 3), and the triangles as int64
    (F x 3, 0-based), polygons fan-triangulated from their first corner. Indices may be 1-based
    or negative (relative to the vertices read so far); `v/vt/vn` corners use the first number.
    Other lines are ignored."""
    tokens, faces = [], []
    with open(path, "r", encoding="utf-8", errors="replace") as fh:
        for lineno, line in enumerate(fh, 1):
            parts = line.split()
            if not parts:
                continue
            tag = parts[0]
            if tag == "v":
                if len(parts) < 4:
                    raise ValueError(f"{path}:{lineno}: vertex with fewer than 3 coordinates")
                tokens.append(parts[1:4])
            elif tag == "f":
                n = len(tokens)
                idx = []
                for p in parts[1:]:
                    i = int(p.split("/", 1)[0])
                    if i > 0:
                        i -= 1
                    elif i < 0:
                        i += n
                    else:
                        raise ValueError(f"{path}:{lineno}: vertex index 0")
                    if not 0 <= i < n:
                        raise ValueError(f"{path}:{lineno}: vertex index {p} out of range ({n} vertices so far)")
                    idx.append(i)
                if len(idx) < 3:
                    raise ValueError(f"{path}:{lineno}: face with fewer than 3 corners")
                first = idx[0]
                for k in range(1, len(idx) - 1):
                    faces.append((first, idx[k], idx[k + 1]))
    positions = np.array(tokens, dtype=np.float64).reshape(-1, 3)
    triangles = np.array(faces, dtype=np.int64).reshape(-1, 3)
    return tokens, positions, triangles


def run_xatlas(positions, triangles):
    """xatlas at default options. Returns (vmapping, indices, uvs, info)."""
    atlas = xatlas.Atlas()
    atlas.add_mesh(np.ascontiguousarray(positions, dtype=np.float32),
                   np.ascontiguousarray(triangles, dtype=np.uint32))
    atlas.generate()  # default ChartOptions() and PackOptions(), as xatlas.parametrize
    vmapping, indices, uvs = atlas.get_mesh(0)
    info = {
        "charts_reported_by_xatlas": int(atlas.chart_count),
        "atlas_count": int(atlas.atlas_count),
        "atlas_width": int(atlas.width),
        "atlas_height": int(atlas.height),
        "utilization_reported_by_xatlas": float(np.mean(atlas.utilization)),
    }
    return vmapping, indices, uvs, info


def write_atlas_obj(path, tokens, triangles, vmapping, indices, uvs, header):
    """Input positions verbatim, xatlas' UVs per output vertex, input faces with `v/vt` corners."""
    if indices.shape[0] != triangles.shape[0]:
        raise RuntimeError(f"xatlas returned {indices.shape[0]} faces for {triangles.shape[0]} input faces")
    mapped = vmapping.astype(np.int64)[indices.astype(np.int64)]
    bad = np.flatnonzero(np.any(mapped != triangles, axis=1))
    if bad.size:
        raise RuntimeError(f"xatlas changed the corners of {bad.size} faces (first: face {int(bad[0])})")
    tmp = path + ".tmp"
    with open(tmp, "w", newline="\n") as fh:
        for line in header:
            fh.write("# " + line + "\n")
        fh.write("".join("v %s %s %s\n" % tuple(t) for t in tokens))
        fh.write("".join("vt %.9g %.9g\n" % (u, v) for u, v in uvs.tolist()))
        f = np.empty((triangles.shape[0], 6), dtype=np.int64)
        f[:, 0::2] = triangles + 1
        f[:, 1::2] = indices.astype(np.int64) + 1
        fh.write("".join("f %d/%d %d/%d %d/%d\n" % tuple(r) for r in f.tolist()))
    os.replace(tmp, path)


def unwrap_one(mesh, out_dir):
    """Unwraps one mesh into out_dir; returns the xatlas.json contents (with "error" on failure)."""
    os.makedirs(out_dir, exist_ok=True)
    atlas_path = os.path.join(out_dir, "atlas.obj")
    for stale in (atlas_path, os.path.join(out_dir, "xatlas.json")):
        if os.path.exists(stale):
            os.remove(stale)
    rec = {
        "input": os.path.abspath(mesh),
        "options": "xatlas defaults (ChartOptions(), PackOptions())",
        "xatlas_version": getattr(xatlas, "__version__", "unknown"),
        "numpy_version": np.__version__,
    }
    t_start = time.perf_counter()
    try:
        tokens, positions, triangles = read_obj(mesh)
        rec["vertices"] = int(positions.shape[0])
        rec["faces"] = int(triangles.shape[0])
        if triangles.shape[0] == 0:
            raise ValueError("no faces")
        t0 = time.perf_counter()
        vmapping, indices, uvs, info = run_xatlas(positions, triangles)
        rec["seconds"] = time.perf_counter() - t0
        rec.update(info)
        rec["output_vertices"] = int(vmapping.shape[0])
        header = [
            f"xatlas {rec['xatlas_version']} at default options on {os.path.basename(mesh)}",
            f"{rec['vertices']} vertices (input order), {rec['output_vertices']} vt, {rec['faces']} faces (input order)",
            f"charts reported by xatlas: {rec['charts_reported_by_xatlas']}",
        ]
        write_atlas_obj(atlas_path, tokens, triangles, vmapping, indices, uvs, header)
        rec["seconds_with_io"] = time.perf_counter() - t_start
        rec["atlas"] = os.path.abspath(atlas_path)
    except Exception as e:  # noqa: BLE001 -- any failure is recorded and the run goes on
        rec["error"] = f"{type(e).__name__}: {e}"
        rec["traceback"] = traceback.format_exc()
        rec["seconds_with_io"] = time.perf_counter() - t_start
    write_json(os.path.join(out_dir, "xatlas.json"), rec)
    return rec


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 epilog="Writes DIR/<name>/atlas.obj and DIR/<name>/xatlas.json per mesh.")
    ap.add_argument("meshes", nargs="+", metavar="MESH", help="input OBJ (v/f lines)")
    ap.add_argument("-o", "--out", required=True, metavar="DIR", help="output folder")
    ap.add_argument("--name", help="output subfolder name (one input only; default: file name without .obj)")
    a = ap.parse_args(argv)
    if a.name and len(a.meshes) != 1:
        ap.error("--name needs exactly one MESH")

    failed = 0
    for mesh in a.meshes:
        name = a.name or os.path.splitext(os.path.basename(mesh))[0]
        rec = unwrap_one(mesh, os.path.join(a.out, name))
        if "error" in rec:
            failed += 1
            print(f"{name}: FAILED: {rec['error']}", flush=True)
        else:
            print(f"{name}: {rec['faces']} faces, {rec['charts_reported_by_xatlas']} charts, "
                  f"xatlas {rec['seconds']:.2f} s ({rec['seconds_with_io']:.2f} s with I/O)", flush=True)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
