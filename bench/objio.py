"""The few lines of OBJ reading the bench scripts share: vertices and triangles, nothing else."""
import numpy as np


def read_obj(path):
    """Vertices (float64, V×3) and triangles (int64, F×3) of an OBJ: `v` and `f` lines only,
    1-based or negative (relative) indices, polygons fan-triangulated."""
    verts, faces = [], []
    with open(path) as f:
        for line in f:
            parts = line.split()
            if not parts:
                continue
            if parts[0] == "v":
                verts.append([float(x) for x in parts[1:4]])
            elif parts[0] == "f":
                idx = [int(p.split("/")[0]) for p in parts[1:]]
                idx = [i - 1 if i > 0 else len(verts) + i for i in idx]
                for k in range(1, len(idx) - 1):
                    faces.append([idx[0], idx[k], idx[k + 1]])
    return np.array(verts, dtype=np.float64), np.array(faces, dtype=np.int64)
