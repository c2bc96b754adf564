#!/usr/bin/env python3
"""The UV-atlas benchmark: nuvo against xatlas on Common Shapes and on unruly geometry.

    bash bench/setup_venv.sh                       # once: bench/.venv with xatlas, numpy, ...
    cargo build --release --bin nuvo               # once: target/release/nuvo
    bench/.venv/bin/python bench/suite.py --out /tmp/suite

Items (see bench/README.md):
  common_shapes  every *.obj in DATA/benchmark/common_shapes/
  unruly         meshes/unruly_bunny.obj, meshes/unruly_vase.obj, density/unruly_bunny.npy,
                 density/unruly_vase.npy, pointclouds/stanford-bunny_200k.ply
  generated      with --unruly-from: unruly meshes and density grids made here by
                 DATA/../tools/make_unruly.py from common-shapes meshes (into OUT/generated/)

Per item, in one sitting and item by item:
  nuvo    `nuvo unwrap INPUT -o OUT/nuvo/NAME` (log in unwrap.log, wall time measured here), then
          OUT/nuvo/NAME/metrics.json is read.
  xatlas  (meshes only) bench/xatlas_unwrap.py at default options -> OUT/xatlas/NAME/atlas.obj,
          scored by `nuvo eval atlas.obj --json` (16 views at 800 px) -> OUT/xatlas/NAME/eval.json.
          A density grid is compared with xatlas on its own marching-cubes mesh (the matching
          meshes/unruly_*.obj, where the nuvo atlas goes too); a point cloud has no xatlas row.
Writes OUT/suite.md and OUT/suite.csv after every item.
"""
import argparse
import csv
import datetime
import io
import json
import os
import platform
import re
import shlex
import shutil
import signal
import statistics
import subprocess
import sys
import time

from benchio import read_json, write_json

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
XATLAS_SCRIPT = os.path.join(HERE, "xatlas_unwrap.py")
RECORD = "suite_item.json"  # written last, atomically: its presence with status "ok" = item complete

TOOLS = ("nuvo", "xatlas")


# ----------------------------------------------------------------------------------------------
# items
# ----------------------------------------------------------------------------------------------

class Item:
    """One benchmark input.

    kind: "mesh", "density" or "pointcloud". xatlas_mesh: the OBJ xatlas unwraps for the
    comparison (None: no xatlas row), xatlas_name: the folder under OUT/xatlas/ (a density grid
    shares its matching mesh's). prepare: None, or a callable that makes the input (generated
    items) and raises on failure."""

    def __init__(self, group, name, kind, path, xatlas_mesh=None, xatlas_name=None, prepare=None, note="",
                 nuvo_args=()):
        self.group, self.name, self.kind, self.path = group, name, kind, path
        self.nuvo_args = list(nuvo_args)
        self.xatlas_mesh = xatlas_mesh
        self.xatlas_name = xatlas_name or (name if xatlas_mesh else None)
        self.prepare = prepare
        self.note = note

    def __repr__(self):
        return f"Item({self.group}/{self.name}: {self.path})"


def matching_mesh(npy_path, data):
    """The marching-cubes mesh of a density grid: its header's "mesh" field, else meshes/<stem>.obj."""
    hdr_path = os.path.splitext(npy_path)[0] + ".json"
    try:
        with open(hdr_path) as fh:
            rel = json.load(fh).get("mesh")
        if rel:
            return os.path.normpath(os.path.join(os.path.dirname(npy_path), rel))
    except (OSError, ValueError):
        pass
    return os.path.join(data, "meshes", os.path.splitext(os.path.basename(npy_path))[0] + ".obj")


def common_shapes_items(data):
    folder = os.path.join(data, "benchmark", "common_shapes")
    if not os.path.isdir(folder):
        raise SystemExit(f"suite.py: no folder {folder} (set --data or NUVO_DATA)")
    items = []
    for f in sorted(os.listdir(folder)):
        if f.endswith(".obj"):
            p = os.path.join(folder, f)
            items.append(Item("common_shapes", f[:-4], "mesh", p, xatlas_mesh=p))
    return items


def unruly_items(data):
    items = []
    for stem in ("unruly_bunny", "unruly_vase"):
        p = os.path.join(data, "meshes", stem + ".obj")
        items.append(Item("unruly", stem, "mesh", p, xatlas_mesh=p))
    for stem in ("unruly_bunny", "unruly_vase"):
        p = os.path.join(data, "density", stem + ".npy")
        mesh = matching_mesh(p, data)
        items.append(Item("unruly", stem + "_density", "density", p, xatlas_mesh=mesh,
                          xatlas_name=os.path.splitext(os.path.basename(mesh))[0],
                          note=f"xatlas on {os.path.relpath(mesh, data)}"))
    # A point cloud has no mesh of its own: the atlas is baked onto the bunny mesh it was sampled
    # from, so it can be measured like the others.
    p = os.path.join(data, "pointclouds", "stanford-bunny_200k.ply")
    bunny = os.path.join(data, "meshes", "stanford-bunny.obj")
    items.append(Item("unruly", "stanford-bunny_200k", "pointcloud", p,
                      nuvo_args=["--set", f"output.bake_mesh={bunny}"],
                      note="baked onto meshes/stanford-bunny.obj"))
    return items


def generated_items(args, data, out):
    """The "generated" group (issue 25): for each common-shapes mesh named in --unruly-from, an
    unruly mesh and its density grid made by make_unruly.py into OUT/generated/ (not committed
    anywhere). The files are made when the item first runs (and kept: a later sitting, with or
    without --resume, reuses them). Needs scipy and scikit-image (bench/setup_venv.sh)."""
    if not args.unruly_from:
        return []
    tool = os.path.join(os.path.dirname(os.path.abspath(data)), "tools", "make_unruly.py")
    src_dir = os.path.join(data, "benchmark", "common_shapes")
    if args.unruly_from.strip() == "all":
        names = [f[:-4] for f in sorted(os.listdir(src_dir)) if f.endswith(".obj")]
    else:
        names = [n.strip() for n in args.unruly_from.split(",") if n.strip()]
    gen = os.path.join(out, "generated")
    items = []
    for name in names:
        src = os.path.join(src_dir, name + ".obj")
        if not os.path.exists(src):
            raise SystemExit(f"suite.py: --unruly-from {name}: no {src}")
        stem = name + "_unruly"
        obj, prefix = os.path.join(gen, stem + ".obj"), os.path.join(gen, stem)
        prepare = _generator(tool, src, obj, prefix, args.unruly_seed, args.unruly_args, args.timeout)
        items.append(Item("generated", stem, "mesh", obj, xatlas_mesh=obj, prepare=prepare,
                          note=f"make_unruly.py on {name}.obj, seed {args.unruly_seed}"))
        items.append(Item("generated", stem + "_density", "density", prefix + ".npy", xatlas_mesh=obj,
                          xatlas_name=stem, prepare=prepare, note=f"xatlas on generated/{stem}.obj"))
    return items


def _generator(tool, src, obj, prefix, seed, extra, timeout):
    done_marker = prefix + ".stats.json"  # make_unruly writes it last

    def prepare():
        if all(os.path.exists(p) for p in (obj, prefix + ".npy", prefix + ".json", done_marker)):
            return
        os.makedirs(os.path.dirname(obj), exist_ok=True)
        cmd = [sys.executable, tool, "--shape", "mesh", "--mesh", src, "--seed", str(seed), "--out", obj,
               "--density-out", prefix, "--stats-json", done_marker + ".tmp"] + shlex.split(extra or "")
        rc, wall, reason = run_logged(cmd, prefix + ".log", timeout)
        if rc != 0:
            raise RuntimeError(f"make_unruly.py failed: {reason}")
        os.replace(done_marker + ".tmp", done_marker)

    return prepare


def select(items, only):
    if not only:
        return items
    wanted = [w.strip() for w in only.split(",") if w.strip()]
    known = {i.name for i in items} | {i.group for i in items}
    unknown = [w for w in wanted if w not in known]
    if unknown:
        raise SystemExit(f"suite.py: --only: unknown {', '.join(unknown)}; items: "
                         + ", ".join(i.name for i in items) + "; groups: "
                         + ", ".join(sorted({i.group for i in items})))
    return [i for i in items if i.name in wanted or i.group in wanted]


# ----------------------------------------------------------------------------------------------
# running things
# ----------------------------------------------------------------------------------------------

def run_logged(cmd, log_path, timeout, stdout_path=None, stats=None):
    """Runs cmd in its own process group with stdout+stderr into log_path (stdout into stdout_path
    instead, if given). Returns (returncode or None on timeout, wall seconds, reason or None).
    If `stats` is a dict, it gets the run's CPU seconds and those of other processes on the machine
    meanwhile (`machine_cpu`). On Ctrl-C the child's group is killed and KeyboardInterrupt propagates."""
    os.makedirs(os.path.dirname(os.path.abspath(log_path)), exist_ok=True)
    with open(log_path, "w") as log:
        log.write("$ " + shlex.join(cmd) + "\n")
        log.flush()
        out = open(stdout_path, "w") if stdout_path else log
        try:
            cpu0, busy0 = _children_cpu(), _machine_busy()
            t0 = time.perf_counter()
            try:
                p = subprocess.Popen(cmd, stdout=out, stderr=log, stdin=subprocess.DEVNULL,
                                     start_new_session=True, cwd=REPO)
            except OSError as e:
                return 127, 0.0, f"cannot start {cmd[0]}: {e}"
            try:
                rc = p.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                _kill_group(p)
                wall = time.perf_counter() - t0
                log.write(f"\n[suite.py] killed after the {timeout:g} s timeout\n")
                return None, wall, f"timeout after {timeout:g} s"
            except BaseException:
                _kill_group(p)
                log.write("\n[suite.py] interrupted\n")
                raise
            wall = time.perf_counter() - t0
            if stats is not None:
                stats.update(machine_cpu(wall, _children_cpu() - cpu0, busy0, _machine_busy()))
        finally:
            if stdout_path:
                out.close()
    if rc != 0:
        return rc, wall, f"exit {rc}: {last_error_line(log_path)}"
    return rc, wall, None


def _children_cpu():
    """User + system CPU seconds of this process's waited-for children (and theirs) so far."""
    import resource  # noqa: PLC0415 -- POSIX only
    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _machine_busy():
    """Busy CPU seconds of the whole machine since boot (/proc/stat), None where unreadable."""
    try:
        with open("/proc/stat") as fh:
            f = [int(x) for x in fh.readline().split()[1:]]
        idle = f[3] + (f[4] if len(f) > 4 else 0)  # idle + iowait
        busy = sum(f[:8]) - idle  # user nice system idle iowait irq softirq steal
        return busy / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError):
        return None


def machine_cpu(wall, own_cpu, busy0, busy1):
    """What else ran during a timed run: `other_cpu_share` is the CPU time of other processes over
    the machine's capacity (wall x cores) in that time, 0 on an otherwise idle machine."""
    st = {"cpu_seconds": round(own_cpu, 3)}
    if busy0 is not None and busy1 is not None and wall > 0:
        other = max(0.0, (busy1 - busy0) - own_cpu)
        st["other_cpu_seconds"] = round(other, 2)
        st["other_cpu_share"] = round(other / (wall * (os.cpu_count() or 1)), 3)
    return st


def _kill_group(p):
    try:
        os.killpg(p.pid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass
    p.wait()


def last_error_line(log_path):
    """The most telling line of a log: the last one mentioning an error, else the last line."""
    try:
        with open(log_path, errors="replace") as fh:
            lines = [l.strip() for l in fh if l.strip() and not l.startswith("$ ")]
    except OSError:
        return "(no log)"
    if not lines:
        return "(no output)"
    for l in reversed(lines):
        if re.search(r"error|panick|Traceback|Killed|unrecognized", l, re.I):
            return l[:300]
    return lines[-1][:300]


def load_average():
    """The 1-minute load average (None where the OS has none): timings taken at a load well above
    zero on an otherwise idle benchmark machine were shared with something else."""
    try:
        return round(os.getloadavg()[0], 2)
    except (AttributeError, OSError):
        return None


def binary_built(path):
    """The modification time of a binary (which build of nuvo ran), None if missing."""
    try:
        return datetime.datetime.fromtimestamp(os.stat(path).st_mtime, datetime.timezone.utc).isoformat(
            timespec="seconds")
    except OSError:
        return None


def now():
    return datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")


def complete_record(folder):
    rec = read_json(os.path.join(folder, RECORD))
    return rec if rec and rec.get("status") == "ok" else None


def run_nuvo(item, args, out):
    """`nuvo unwrap` on one item -> the record written to OUT/nuvo/NAME/suite_item.json."""
    d = os.path.join(out, "nuvo", item.name)
    if os.path.isdir(d):
        shutil.rmtree(d)  # a fresh run folder: no half-finished state from an earlier sitting
    os.makedirs(d)
    cmd = [args.nuvo, "unwrap", item.path, "-o", d] + item.nuvo_args + shlex.split(args.nuvo_args or "")
    rec = {"tool": "nuvo", "item": item.name, "group": item.group, "input": item.path,
           "command": shlex.join(cmd), "started": now(), "load_before": load_average(),
           "nuvo_built": binary_built(args.nuvo)}
    stats = {}
    rc, wall, reason = run_logged(cmd, os.path.join(d, "unwrap.log"), args.timeout, stats=stats)
    rec.update(returncode=rc, wall_seconds=wall, seconds=wall, **stats)
    if reason is None:
        m = read_json(os.path.join(d, "metrics.json"))
        if m is None:
            reason = "no readable metrics.json"
        elif not isinstance(m.get("metrics"), dict):
            reason = "metrics.json has no \"metrics\""
    rec.update(status="failed" if reason else "ok", reason=reason, finished=now())
    write_json(os.path.join(d, RECORD), rec)
    return rec


def run_xatlas(item, args, out):
    """xatlas_unwrap.py on item.xatlas_mesh, then `nuvo eval --json` of its atlas -> the record in
    OUT/xatlas/XNAME/suite_item.json."""
    d = os.path.join(out, "xatlas", item.xatlas_name)
    if os.path.isdir(d):
        shutil.rmtree(d)
    os.makedirs(d)
    cmd = [sys.executable, XATLAS_SCRIPT, item.xatlas_mesh, "-o", os.path.join(out, "xatlas"),
           "--name", item.xatlas_name]
    rec = {"tool": "xatlas", "item": item.xatlas_name, "input": item.xatlas_mesh,
           "command": shlex.join(cmd), "started": now(), "load_before": load_average()}
    stats = {}
    rc, wall, reason = run_logged(cmd, os.path.join(d, "unwrap.log"), args.timeout, stats=stats)
    rec.update(returncode=rc, wall_seconds=wall, **stats)
    xj = read_json(os.path.join(d, "xatlas.json"))
    if xj and xj.get("error"):
        reason = "xatlas: " + xj["error"]
    elif reason is None and not xj:
        reason = "no readable xatlas.json"
    if xj:
        rec["seconds"] = xj.get("seconds")
        rec["seconds_with_io"] = xj.get("seconds_with_io")
    if reason is None:
        reason = evaluate_xatlas(d, args, rec)
    rec.update(status="failed" if reason else "ok", reason=reason, finished=now())
    write_json(os.path.join(d, RECORD), rec)
    return rec


def evaluate_xatlas(d, args, rec):
    """`nuvo eval atlas.obj --json` -> eval.json; returns a failure reason or None."""
    cmd = [args.nuvo, "eval", os.path.join(d, "atlas.obj"), "--json"]
    rec["eval_command"] = shlex.join(cmd)
    rec["nuvo_built"] = binary_built(args.nuvo)
    tmp = os.path.join(d, "eval.json.tmp")
    rc, wall, reason = run_logged(cmd, os.path.join(d, "eval.log"), args.timeout, stdout_path=tmp)
    rec["eval_seconds"] = wall
    if reason:
        return "nuvo eval: " + reason
    ej = read_json(tmp)
    if not ej or not isinstance(ej.get("metrics"), dict):
        return "nuvo eval printed no JSON with \"metrics\""
    os.replace(tmp, os.path.join(d, "eval.json"))
    return None


def reevaluate_xatlas(xname, args, out):
    """--re-eval: score an existing xatlas atlas again with the current `nuvo eval`."""
    d = os.path.join(out, "xatlas", xname)
    rec = read_json(os.path.join(d, RECORD))
    if not rec or not os.path.exists(os.path.join(d, "atlas.obj")):
        return None
    reason = evaluate_xatlas(d, args, rec)
    rec.update(status="failed" if reason else "ok", reason=reason, re_evaluated=now())
    write_json(os.path.join(d, RECORD), rec)
    return rec


# ----------------------------------------------------------------------------------------------
# rows and tables
# ----------------------------------------------------------------------------------------------

COLUMNS = [  # (key, md header, md format)
    ("group", "group", None),
    ("item", "item", None),
    ("tool", "tool", None),
    ("success", "success", None),
    ("faces", "faces", "{:d}"),
    ("time_s", "time s", "{:.2f}"),
    ("charts", "charts", "{:d}"),
    ("seam_length", "seam length", "{:.2f}"),
    ("angular", "angular ↑", "{:.3f}"),
    ("area_distortion", "area dist. ↓", "{:.3f}"),
    ("overall_area_distortion", "overall area ↓", "{:.3f}"),
    ("texel_aspect", "texel aspect ↓", "{:.3f}"),
    ("packing_efficiency", "packing eff. ↑", "{:.3f}"),
    ("boundary", "Boundary ↑", "{:.4f}"),
    ("stretch", "Stretch ↑", "{:.4f}"),
    ("conformal", "Conformal ↑", "{:.4f}"),
    ("editability", "Editability ↑", "{:.4f}"),
    ("flipped_faces", "flipped faces", "{:d}"),
    ("overlapping_faces", "overlapping faces", "{:d}"),
]
CSV_EXTRA = ["input", "note", "reason", "proxy", "charts_source", "uv_charts", "charts_reported_by_xatlas",
             "utilisation", "texel_aspect_p90", "xatlas_seconds_with_io", "process_wall_seconds", "eval_seconds",
             "eval_views", "eval_resolution", "bake_faces", "bake_flipped_faces", "bake_overlapping_faces",
             "cpu_seconds", "other_cpu_share", "load_before", "nuvo_built", "finished"]


def _get(d, *keys):
    for k in keys:
        if not isinstance(d, dict):
            return None
        d = d.get(k)
    return d


def _num(x, integer=False):
    if isinstance(x, bool) or x is None:
        return None
    if isinstance(x, (int, float)):
        return int(x) if integer else float(x)
    return None


def metrics_row(m):
    """The table's numbers from a Metrics object (metrics.json's or nuvo eval's "metrics")."""
    pu = _get(m, "partuv") or {}
    uv = _get(m, "uv") or {}
    img = _get(m, "image") or {}
    charts = _num(pu.get("charts"), True)
    src = "partuv"
    if charts is None and _num(uv.get("charts"), True) is not None:
        charts, src = _num(uv.get("charts"), True), "uv"  # same definition: faces sharing an edge and its UVs
    return {
        "faces": _num(uv.get("faces"), True),
        "charts": charts,
        "charts_source": src if charts is not None else "",
        "uv_charts": _num(uv.get("charts"), True),
        "seam_length": _num(pu.get("seam_length")),
        "angular": _num(pu.get("angular_score")),
        "area_distortion": _num(pu.get("area_distortion")),
        "overall_area_distortion": _num(pu.get("overall_area_distortion")),
        "packing_efficiency": _num(pu.get("packing_efficiency")),
        "boundary": _num(img.get("boundary")),
        "stretch": _num(img.get("stretch")),
        "conformal": _num(img.get("conformal")),
        "editability": _num(img.get("editability")),
        "flipped_faces": _num(uv.get("flipped_faces"), True),
        "overlapping_faces": _num(uv.get("overlapping_faces"), True),
        "utilisation": _num(uv.get("utilisation")),
        "texel_aspect": _num(uv.get("texel_aspect_median")),
        "texel_aspect_p90": _num(uv.get("texel_aspect_p90")),
        "eval_views": _num(_get(m, "options", "views"), True),
        "eval_resolution": _num(_get(m, "options", "resolution"), True),
    }


def run_fields(rec):
    """The columns every tool run's record fills the same way."""
    return {"finished": rec.get("finished"), "load_before": rec.get("load_before"),
            "nuvo_built": rec.get("nuvo_built"), "cpu_seconds": rec.get("cpu_seconds"),
            "other_cpu_share": rec.get("other_cpu_share"), "process_wall_seconds": rec.get("wall_seconds")}


def nuvo_row(item, rec, out):
    row = {"group": item.group, "item": item.name, "tool": "nuvo", "input": item.path, "note": ""}
    if rec is None:
        return None
    row.update(run_fields(rec))
    if rec.get("status") != "ok":
        row.update(success="no: " + str(rec.get("reason")), reason=rec.get("reason"))
        return row
    m = read_json(os.path.join(out, "nuvo", item.name, "metrics.json")) or {}
    row.update(metrics_row(m.get("metrics")))
    row["time_s"] = rec.get("wall_seconds")
    bake = m.get("bake") or {}
    row["bake_faces"] = _num(bake.get("faces"), True)
    row["bake_flipped_faces"] = _num(bake.get("flipped_faces"), True)
    row["bake_overlapping_faces"] = _num(bake.get("overlapping_faces"), True)
    if row.get("faces") is None:
        row["faces"] = row["bake_faces"]
    row["success"] = "yes"
    return row


def xatlas_row(item, rec, out):
    row = {"group": item.group, "item": item.name, "tool": "xatlas", "input": item.xatlas_mesh or "",
           "note": item.note if item.kind == "density" else ""}
    if item.xatlas_mesh is None:
        row.update(success="n/a", reason=f"xatlas takes no {item.kind}", note=f"xatlas takes no {item.kind}")
        return row
    if rec is None:
        return None
    row.update(run_fields(rec))
    row["xatlas_seconds_with_io"] = rec.get("seconds_with_io")
    row["eval_seconds"] = rec.get("eval_seconds")
    xj = read_json(os.path.join(out, "xatlas", item.xatlas_name, "xatlas.json")) or {}
    row["charts_reported_by_xatlas"] = xj.get("charts_reported_by_xatlas")
    if rec.get("status") != "ok":
        row.update(success="no: " + str(rec.get("reason")), reason=rec.get("reason"))
        row["faces"] = xj.get("faces")
        return row
    ej = read_json(os.path.join(out, "xatlas", item.xatlas_name, "eval.json")) or {}
    row.update(metrics_row(ej.get("metrics")))
    if row.get("faces") is None:
        row["faces"] = xj.get("faces")
    row["time_s"] = rec.get("seconds")
    row["success"] = "yes"
    return row


def fmt(v, f):
    if v is None or v == "":
        return ""
    if f is None:
        return str(v)
    try:
        return f.format(v)
    except (ValueError, TypeError):
        return str(v)


def md_cell(s, limit=None):
    s = str(s).replace("|", "\\|").replace("\n", " ")
    if limit and len(s) > limit:
        s = s[: limit - 1] + "…"
    return s


def md_table(headers, rows):
    out = ["| " + " | ".join(headers) + " |", "|" + "|".join("---" for _ in headers) + "|"]
    out += ["| " + " | ".join(md_cell(c) for c in r) + " |" for r in rows]
    return "\n".join(out)


def _vals(rows, key):
    return [r[key] for r in rows if isinstance(r.get(key), (int, float)) and not isinstance(r.get(key), bool)]


def _mean(v):
    return statistics.fmean(v) if v else None


def _median(v):
    return statistics.median(v) if v else None


SHARED_LIMIT = 0.10  # other_cpu_share above which a timing is marked as taken on a shared machine


def shared(row):
    share = row.get("other_cpu_share")
    return isinstance(share, (int, float)) and share > SHARED_LIMIT


def aggregate(rows):
    """Per tool and group, like the PartUV paper's table. Rows that are n/a (point clouds for
    xatlas) and xatlas rows standing in for a density grid (a copy of its mesh's row) are left out."""
    groups = []
    for r in rows:
        if (r["tool"], r["group"]) not in groups:
            groups.append((r["tool"], r["group"]))
    table = []
    for tool, group in sorted(groups, key=lambda tg: (TOOLS.index(tg[0]) if tg[0] in TOOLS else 9, tg[1])):
        rs = [r for r in rows if r["tool"] == tool and r["group"] == group
              and r["success"] != "n/a" and not r.get("proxy")]
        if not rs:
            continue
        ok = [r for r in rs if r["success"] == "yes"]
        table.append([
            tool, group, f"{len(ok)}/{len(rs)} ({100.0 * len(ok) / len(rs):.0f}%)",
            "{} / {}".format(fmt(_mean(_vals(ok, "charts")), "{:.1f}"), fmt(_median(_vals(ok, "charts")), "{:g}"))
            if _vals(ok, "charts") else "",
            fmt(_median(_vals(ok, "seam_length")), "{:.2f}"),
            fmt(_mean(_vals(ok, "angular")), "{:.3f}"),
            fmt(_mean(_vals(ok, "area_distortion")), "{:.3f}"),
            fmt(_mean(_vals(ok, "overall_area_distortion")), "{:.3f}"),
            fmt(_mean(_vals(ok, "packing_efficiency")), "{:.3f}"),
            fmt(_mean(_vals(ok, "editability")), "{:.4f}"),
            fmt(_mean(_vals(ok, "time_s")), "{:.2f}") + (" †" if any(shared(r) for r in ok) else ""),
        ])
    return table


def cpu_info():
    model, flags = platform.processor() or "unknown", set()
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                k, _, v = line.partition(":")
                k = k.strip()
                if k == "model name" and model in ("unknown", "", platform.processor()):
                    model = v.strip()
                elif k == "flags" and not flags:
                    flags = set(v.split())
    except OSError:
        pass
    simd = "AVX-512" if "avx512f" in flags else ("AVX2" if "avx2" in flags else "no AVX2")
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:
        cores = os.cpu_count()
    return model, simd, cores


def git_commit():
    try:
        rev = subprocess.run(["git", "-C", REPO, "rev-parse", "--short=12", "HEAD"], capture_output=True,
                             text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "-C", REPO, "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True).stdout.strip()
        return rev + (" (with uncommitted changes in tracked files)" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def tool_versions(args):
    v = {}
    try:
        v["nuvo"] = subprocess.run([args.nuvo, "--version"], capture_output=True, text=True,
                                   timeout=30).stdout.strip() or "?"
        shown = os.path.relpath(args.nuvo, REPO) if args.nuvo.startswith(REPO) else args.nuvo
        v["nuvo"] += f" ({shown}, built {binary_built(args.nuvo)})"
    except (OSError, subprocess.SubprocessError):
        v["nuvo"] = "not found"
    try:
        import xatlas  # noqa: PLC0415
        v["xatlas"] = "xatlas (python) " + getattr(xatlas, "__version__", "?")
    except ImportError:
        v["xatlas"] = "xatlas not importable by " + sys.executable
    return v


def write_report(out, rows, meta):
    rows = [r for r in rows if r is not None]
    # CSV: every column, plain numbers.
    keys = [k for k, _, _ in COLUMNS] + CSV_EXTRA
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(keys)
    for r in rows:
        w.writerow(["" if r.get(k) is None else r.get(k) for k in keys])
    _atomic_write(os.path.join(out, "suite.csv"), buf.getvalue())

    model, simd, cores = meta["cpu"]
    lines = [
        "# UV-atlas benchmark: nuvo and xatlas",
        "",
        f"- date: {meta['date']}",
        f"- CPU: {model} ({simd}), {cores} cores",
        f"- repo commit: {meta['commit']}",
        f"- tools: {meta['versions']['nuvo']}; {meta['versions']['xatlas']} at default options",
        f"- command: `{meta['command']}` (in `{meta['cwd']}`)",
        f"- per-item timeout: {meta['timeout']:g} s" + (f"; extra nuvo arguments: `{meta['nuvo_args']}`"
                                                      if meta.get("nuvo_args") else ""),
    ]
    lines.append(f"- 1-minute load average: {meta['load_start']} at the start, {load_average()} now "
                 "(each run's, before it started, is `load_before` in `suite.csv`)")
    builds = sorted({r["nuvo_built"] for r in rows if r.get("nuvo_built")})
    if len(builds) > 1 or (builds and builds[0] != binary_built(meta["nuvo"])):
        lines.append("- **the runs used nuvo binaries built at** " + ", ".join(builds)
                     + " (`nuvo_built` in `suite.csv`)")
    present = {r["tool"] for r in rows}
    missing = [f"{i.name} ({tool})" for i in meta["items"] for tool in TOOLS
               if tool in present and not any(r["item"] == i.name and r["tool"] == tool for r in rows)]
    if missing:
        lines.append(f"- not run (yet): {', '.join(missing)}")
    if meta.get("resumed"):
        lines.append(f"- resumed: {meta['resumed']} tool runs taken from earlier sittings (their "
                     "`suite_item.json` has the date)")
    def cell(r, k, f):
        text = fmt(r.get(k), f)
        if k == "time_s" and text and shared(r):
            text += " †"
        return md_cell(text, 90 if k == "success" else None)

    lines += ["", "## Per item", "",
              md_table([h for _, h, _ in COLUMNS], [[cell(r, k, f) for k, _, f in COLUMNS] for r in rows]), ""]
    notes = [
        "- time s: nuvo, the wall time of the whole `nuvo unwrap` process (reading, training, baking, "
        "exports, its own metrics); xatlas, the xatlas call alone (`suite.csv` has it with OBJ I/O "
        "as `xatlas_seconds_with_io`). Measured in one sitting, item by item, on this machine.",
        "- charts, seam length, angular, area distortion (worst chart), overall area distortion, packing "
        "efficiency: the PartUV comparison's metrics (`metrics.partuv`, data/benchmark/README.md); empty "
        "where the nuvo binary did not report them. Where `metrics.partuv` is missing, charts are "
        "`metrics.uv.charts`, the same definition (faces sharing an edge and its UVs); `suite.csv` "
        "says which in `charts_source`.",
        "- Boundary, Stretch, Conformal, Editability: the Nuvo paper's metrics. xatlas atlases are scored "
        "by `nuvo eval --json` (16 views at 800 px); nuvo's by its own run (`eval_views`, "
        "`eval_resolution` in `suite.csv`).",
        f"- †: other processes used more than {SHARED_LIMIT:.0%} of the machine's CPU time while that run "
        "was timed (`other_cpu_share` in `suite.csv`, from /proc/stat): its time is not a clean measurement.",
        "- flipped and overlapping faces: `metrics.uv` for both tools (the nuvo bake's own counts are "
        "in `suite.csv` as `bake_*`).",
        "- a density grid's xatlas row is xatlas on the grid's marching-cubes mesh (the matching "
        "`meshes/unruly_*.obj`, where the nuvo atlas of the grid goes too): a copy of that mesh's row, "
        "left out of the aggregates. A point cloud has no xatlas row (n/a).",
    ]
    diff = {(r.get("eval_views"), r.get("eval_resolution")) for r in rows if r.get("success") == "yes"}
    if len(diff) > 1:
        notes.append("- **the image metrics were measured at different settings** (views, resolution): "
                     + ", ".join(f"{v}@{res}" for v, res in sorted(diff, key=str)))
    lines += notes + [""]
    lines += ["## Per tool and group", "",
              "Means and medians over the successful items (like the PartUV paper's table).", "",
              md_table(["tool", "group", "success", "mean / median charts", "median seam", "mean angular ↑",
                        "mean area ↓", "mean overall area ↓", "mean packing eff. ↑", "mean Editability ↑",
                        "mean time s"], aggregate(rows)), ""]
    comp = []
    wins = total = 0
    for item in meta["items"]:
        n = next((r for r in rows if r["item"] == item.name and r["tool"] == "nuvo"), None)
        x = next((r for r in rows if r["item"] == item.name and r["tool"] == "xatlas"), None)
        if n is None and x is None:
            continue
        en, ex = (n or {}).get("editability"), (x or {}).get("editability")
        if isinstance(en, float) and isinstance(ex, float):
            mark = "✓" if en >= ex else "✗"
            total += 1
            wins += en >= ex
        else:
            mark = "n/a"
        comp.append([item.group, item.name, fmt(en, "{:.4f}"),
                     fmt(ex, "{:.4f}") + (f" ({item.note})" if item.kind == "density" and ex is not None else ""),
                     fmt(en - ex, "{:+.4f}") if mark != "n/a" else "", mark])
    lines += ["## Editability: nuvo vs xatlas", "",
              f"✓ where nuvo's Editability is at least xatlas': {wins} of {total} items with both.", "",
              md_table(["group", "item", "nuvo", "xatlas", "nuvo − xatlas", "nuvo ≥ xatlas"], comp), ""]
    _atomic_write(os.path.join(out, "suite.md"), "\n".join(lines))


def _atomic_write(path, text):
    tmp = path + ".tmp"
    with open(tmp, "w", newline="\n") as fh:
        fh.write(text)
    os.replace(tmp, path)


# ----------------------------------------------------------------------------------------------
# main
# ----------------------------------------------------------------------------------------------

def parse_args(argv):
    default_data = os.environ.get("NUVO_DATA") or os.path.join(os.path.dirname(REPO), "shared", "data")
    ap = argparse.ArgumentParser(
        description="nuvo vs xatlas on Common Shapes and unruly geometry -> OUT/suite.md, OUT/suite.csv",
        epilog="Run with bench/.venv/bin/python (bash bench/setup_venv.sh makes it). See bench/README.md.")
    ap.add_argument("--out", required=True, metavar="DIR", help="output folder")
    ap.add_argument("--nuvo", default=os.path.join(REPO, "target", "release", "nuvo"),
                    help="the nuvo binary (default: target/release/nuvo); also scores the xatlas atlases")
    ap.add_argument("--data", default=default_data,
                    help=f"the data folder (default: $NUVO_DATA or <repo>/../shared/data = {default_data})")
    ap.add_argument("--only", metavar="NAME,...", help="only these items or groups")
    ap.add_argument("--skip-xatlas", action="store_true", help="do not run xatlas")
    ap.add_argument("--skip-nuvo", action="store_true", help="do not run nuvo unwrap")
    ap.add_argument("--resume", action="store_true",
                    help="keep tool runs whose outputs are complete (suite_item.json with status ok) and "
                         "run the rest, failed ones included; with --skip-*, complete earlier runs of the "
                         "skipped tool still enter the tables")
    ap.add_argument("--re-eval", action="store_true",
                    help="with --resume: score kept xatlas atlases again with the current `nuvo eval` "
                         "(e.g. after nuvo gained metrics)")
    ap.add_argument("--timeout", type=float, default=900.0, help="seconds per tool run (default 900)")
    ap.add_argument("--nuvo-args", default="", metavar="ARGS",
                    help="extra arguments for `nuvo unwrap`, one shell-quoted string")
    ap.add_argument("--list", action="store_true", help="print the items and exit")
    g = ap.add_argument_group("generated unruly group (make_unruly.py; needs scipy, scikit-image)")
    g.add_argument("--unruly-from", metavar="NAME,...|all",
                   help="common-shapes meshes to make unruly variants of, into OUT/generated/")
    g.add_argument("--unruly-seed", type=int, default=25, help="make_unruly.py --seed (default 25)")
    g.add_argument("--unruly-args", default="", metavar="ARGS",
                   help="extra make_unruly.py arguments, e.g. \"--res 160\"")
    return ap.parse_args(argv)


def main(argv=None):
    args = parse_args(argv)
    out = os.path.abspath(args.out)
    data = os.path.abspath(args.data)
    args.nuvo = os.path.abspath(args.nuvo)
    items = select(common_shapes_items(data) + unruly_items(data) + generated_items(args, data, out), args.only)
    if args.list:
        def shown(p):
            return os.path.relpath(p, data) if p.startswith(data + os.sep) else p
        for i in items:
            print(f"{i.group:14s} {i.name:28s} {i.kind:10s} {shown(i.path)}"
                  + (f"   (xatlas: {shown(i.xatlas_mesh)})" if i.xatlas_mesh else ""))
        return 0
    need_nuvo = not (args.skip_nuvo and args.skip_xatlas)
    if need_nuvo and not os.access(args.nuvo, os.X_OK):
        raise SystemExit(f"suite.py: no nuvo binary at {args.nuvo} (cargo build --release --bin nuvo, or --nuvo)")
    if not args.skip_xatlas:
        try:
            import xatlas  # noqa: F401,PLC0415
        except ImportError:
            raise SystemExit(f"suite.py: {sys.executable} cannot import xatlas: run bash bench/setup_venv.sh "
                             "and use bench/.venv/bin/python")
    os.makedirs(out, exist_ok=True)

    meta = {
        "date": now(), "cpu": cpu_info(), "commit": git_commit(), "versions": tool_versions(args),
        "command": shlex.join([os.path.relpath(sys.executable) if sys.executable.startswith(REPO) else sys.executable]
                              + sys.argv), "cwd": os.getcwd(),
        "timeout": args.timeout, "nuvo_args": args.nuvo_args, "items": items, "resumed": 0,
        "load_start": load_average(), "nuvo": args.nuvo,
    }
    records = {}  # (tool, folder name) -> record
    rows_of = {}  # (item name, tool) -> row

    def report():
        rows = []
        for i in items:
            for tool in TOOLS:
                if (i.name, tool) in rows_of:
                    rows.append(rows_of[(i.name, tool)])
        write_report(out, rows, meta)

    def log(msg):
        print(f"[{datetime.datetime.now().strftime('%H:%M:%S')}] {msg}", flush=True)

    interrupted = None

    def on_term(signum, frame):  # a polite kill: stop like Ctrl-C (tool's group killed, tables written)
        raise KeyboardInterrupt(signum)

    signal.signal(signal.SIGTERM, on_term)
    try:
        for n, item in enumerate(items, 1):
            head = f"{n}/{len(items)} {item.group}/{item.name}"
            prepared, prep_error = item.prepare is None, None
            for tool in TOOLS:
                skipped = args.skip_nuvo if tool == "nuvo" else args.skip_xatlas
                if tool == "xatlas" and item.xatlas_mesh is None:
                    if not skipped or args.resume:
                        rows_of[(item.name, tool)] = xatlas_row(item, None, out)
                    continue
                folder = item.name if tool == "nuvo" else item.xatlas_name
                key = (tool, folder)
                rec = records.get(key)
                if rec is None and args.resume:
                    rec = complete_record(os.path.join(out, tool, folder))
                    if rec is not None:
                        meta["resumed"] += 1
                        if tool == "xatlas" and args.re_eval and not skipped:
                            log(f"{head}: xatlas: re-scoring the kept atlas with nuvo eval")
                            rec = reevaluate_xatlas(folder, args, out) or rec
                if rec is None and not skipped:
                    if not prepared:
                        try:
                            log(f"{head}: generating the input")
                            item.prepare()
                        except Exception as e:  # noqa: BLE001
                            prep_error = str(e)
                        prepared = True
                    if prep_error:
                        rec = {"status": "failed", "reason": prep_error}
                    else:
                        what = f" ({item.note})" if tool == "xatlas" and item.note else ""
                        log(f"{head}: {tool}{what} ...")
                        rec = run_nuvo(item, args, out) if tool == "nuvo" else run_xatlas(item, args, out)
                    records[key] = rec
                    if rec.get("status") == "ok":
                        log(f"{head}: {tool} ok in {rec.get('wall_seconds', 0):.1f} s")
                    else:
                        log(f"{head}: {tool} FAILED: {rec.get('reason')}")
                elif rec is not None:
                    records[key] = rec
                if rec is not None:
                    row = nuvo_row(item, rec, out) if tool == "nuvo" else xatlas_row(item, rec, out)
                    row["proxy"] = tool == "xatlas" and item.kind == "density"
                    rows_of[(item.name, tool)] = row
            report()
    except KeyboardInterrupt as e:
        interrupted = 128 + (e.args[0] if e.args else signal.SIGINT)
        log("interrupted: completed items are kept; run again with --resume to go on")
    report()
    print(f"wrote {os.path.join(out, 'suite.md')} and {os.path.join(out, 'suite.csv')}")
    return interrupted or 0


if __name__ == "__main__":
    sys.exit(main())
