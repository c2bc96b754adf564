#!/usr/bin/env bash
# The real-scheduler test of deploy/slurm/: a one-node Slurm cluster on this machine runs
# `nuvo batch` as an array of 3 shards over 6 small generated meshes, then the summary job,
# then the same array again (which must redo nothing).
#
#   sudo tests/slurm/run_slurm_test.sh        # as root: it installs packages and runs slurmd
#
# Environment:
#   NUVO                  the nuvo binary (default: target/release/nuvo of this repo)
#   SLURM_TEST_TIMEOUT    seconds to wait for each submission to end (default 1200)
#   SLURM_TEST_KEEP=1     keep the temporary folder (it is kept anyway when the test fails)
# Installs Debian's slurm-wlm and munge when missing. Everything else (config, munge key, state,
# spool, logs, meshes, outputs) lives in one temporary folder; the daemons it starts (munged,
# slurmctld, slurmd, on two free loopback ports) are stopped at exit. Prints PASS or FAIL last.
set -euo pipefail

REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
NUVO="${NUVO:-${REPO}/target/release/nuvo}"
TIMEOUT="${SLURM_TEST_TIMEOUT:-1200}"
KEEP="${SLURM_TEST_KEEP:-0}"
SHARDS=3
# Settings that make one unwrap take seconds.
FAST_SETS=(training.steps=12 training.batch_3d=256 training.batch_uv=256 model.depth=2 model.width=16
  model.grid_resolution=8 warm_start.samples=2000 output.atlas_resolution=256 output.eval_views=2
  output.eval_resolution=64 output.renders=1 output.render_resolution=64)

# Nothing from an enclosing Slurm job (or another cluster's config) may leak into this one.
while read -r v; do unset "$v"; done < <(compgen -e | grep '^SLURM_' || true)

T=""
REASON=""
PIDS=()          # the daemons this script started: munged, slurmctld, slurmd
JOBS=()          # the job ids it submitted

log() { echo "== $*"; }
fail() { REASON="$*"; exit 1; }

# shellcheck disable=SC2317  # run by the EXIT trap
cleanup() {
  local rc=$?
  set +e
  if [[ -n "${T}" && -f "${T}/slurm.conf" ]]; then
    export SLURM_CONF="${T}/slurm.conf"
    if ((${#JOBS[@]})) && [[ -n "$(squeue -h -j "$(IFS=,; echo "${JOBS[*]}")" 2> /dev/null)" ]]; then
      scancel "${JOBS[@]}" 2> /dev/null
      sleep 3
    fi
    if ((rc != 0)); then
      for f in "${T}"/log/slurmctld.log "${T}"/log/slurmd.log; do
        [[ -f "$f" ]] && { echo "-- last lines of ${f}:"; tail -n 15 "$f"; }
      done
    fi
    scontrol shutdown > /dev/null 2>&1
  fi
  # Wait for the daemons to end, then end any left, each by its own pid.
  local pid n
  for pid in "${PIDS[@]}"; do
    for ((n = 0; n < 20; n++)); do kill -0 "$pid" 2> /dev/null || break; [[ "$n" == 5 ]] && kill "$pid" 2> /dev/null; sleep 0.5; done
    kill -0 "$pid" 2> /dev/null && kill -9 "$pid" 2> /dev/null
  done
  if [[ -n "${T}" ]]; then
    if ((rc == 0)) && [[ "${KEEP}" != 1 ]]; then rm -rf "${T}"; else echo "(kept ${T})"; fi
  fi
  if ((rc == 0)); then
    echo "PASS: ${REASON}"
  else
    echo "FAIL: ${REASON:-exit status ${rc} (see above)}"
  fi
  exit "$rc"
}
trap cleanup EXIT
trap 'REASON="interrupted"; exit 1' INT TERM

[[ "$(id -u)" == 0 ]] || fail "must run as root (it installs packages and runs slurmd, which starts jobs as their users)"
[[ -x "${NUVO}" ]] || fail "no nuvo binary at ${NUVO} (build it, or set NUVO)"
"${NUVO}" batch --help > /dev/null 2>&1 || fail "${NUVO} has no 'batch' subcommand"
command -v python3 > /dev/null || fail "python3 is needed to write the test meshes"

# --- packages
if ! command -v slurmctld > /dev/null || ! command -v slurmd > /dev/null || ! command -v sbatch > /dev/null \
  || ! command -v munged > /dev/null; then
  log "installing slurm-wlm and munge (apt-get)"
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq || fail "apt-get update failed"
  apt-get install -y -qq --no-install-recommends slurm-wlm munge > /dev/null || fail "apt-get install slurm-wlm munge failed"
fi
log "$(slurmctld -V) ($(dpkg-query -W -f='${Package} ${Version}' slurm-wlm 2> /dev/null || echo 'slurm-wlm: not a dpkg install'))"

# --- the private cluster
T="$(mktemp -d /tmp/nuvo-slurm-test.XXXXXX)"
chmod 755 "${T}"    # munged wants every folder above its socket searchable by all
mkdir -p "${T}"/{munge,run,state,spool,log,slurm,work,data,out}
chmod 700 "${T}/munge"
chmod 755 "${T}/run"
log "temporary folder ${T}"

# The node as slurmd itself sees it (name, CPUs, sockets, cores, threads, memory).
NODE_LINE="$(slurmd -C | head -n 1)"
[[ "${NODE_LINE}" == NodeName=* ]] || fail "slurmd -C printed no node line: ${NODE_LINE}"
NODE="$(sed -n 's/^NodeName=\([^ ]*\).*/\1/p' <<< "${NODE_LINE}")"
CPUS="$(sed -n 's/.* CPUs=\([0-9]*\).*/\1/p' <<< "${NODE_LINE}")"
log "node: ${NODE_LINE}"

read -r CTLD_PORT SLURMD_PORT < <(python3 - << 'EOF'
import socket
socks = [socket.socket() for _ in range(2)]
for s in socks:
    s.bind(("127.0.0.1", 0))
print(*(s.getsockname()[1] for s in socks))
EOF
)

dd if=/dev/urandom of="${T}/munge/munge.key" bs=1024 count=1 status=none
chmod 400 "${T}/munge/munge.key"
MUNGE_SOCKET="${T}/run/munge.socket"
munged --foreground --key-file="${T}/munge/munge.key" --socket="${MUNGE_SOCKET}" \
  --pid-file="${T}/run/munged.pid" --log-file="${T}/munge/munged.log" --seed-file="${T}/munge/munged.seed" \
  > "${T}/log/munged.out" 2>&1 &
PIDS+=("$!")
for ((n = 0; n < 50; n++)); do [[ -S "${MUNGE_SOCKET}" ]] && break; sleep 0.2; done
munge -S "${MUNGE_SOCKET}" -n | unmunge -S "${MUNGE_SOCKET}" > /dev/null \
  || fail "munged does not work: $(tail -n 3 "${T}/munge/munged.log" "${T}/log/munged.out" 2> /dev/null)"

cat > "${T}/slurm.conf" << EOF
# A one-node cluster for tests/slurm/run_slurm_test.sh; no accounting database.
ClusterName=nuvotest
SlurmctldHost=${NODE}(127.0.0.1)
SlurmctldPort=${CTLD_PORT}
SlurmdPort=${SLURMD_PORT}
AuthType=auth/munge
AuthInfo=socket=${MUNGE_SOCKET}
CredType=cred/munge
SlurmUser=root
SlurmdUser=root
StateSaveLocation=${T}/state
SlurmdSpoolDir=${T}/spool
SlurmctldPidFile=${T}/run/slurmctld.pid
SlurmdPidFile=${T}/run/slurmd.pid
SlurmctldLogFile=${T}/log/slurmctld.log
SlurmdLogFile=${T}/log/slurmd.log
SlurmctldDebug=info
SlurmdDebug=info
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/filetxt
JobCompLoc=${T}/log/jobcomp.txt
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
MpiDefault=none
ReturnToService=2
MinJobAge=3600
KillWait=10
${NODE_LINE} NodeAddr=127.0.0.1 State=UNKNOWN
PartitionName=test Nodes=${NODE} Default=YES MaxTime=INFINITE State=UP
EOF
export SLURM_CONF="${T}/slurm.conf"

slurmctld -D -f "${SLURM_CONF}" > "${T}/log/slurmctld.out" 2>&1 &
PIDS+=("$!")
slurmd -D -f "${SLURM_CONF}" > "${T}/log/slurmd.out" 2>&1 &
PIDS+=("$!")
state=""
for ((n = 0; n < 60; n++)); do
  state="$(sinfo -h -n "${NODE}" -o %t 2> /dev/null || true)"
  [[ "${state}" == idle ]] && break
  sleep 1
done
[[ "${state}" == idle ]] || fail "the node is not idle after 60 s (sinfo: '${state}')"
log "sinfo"
sinfo

# --- the meshes and the manifest
python3 - "${T}/data" << 'EOF'
import math, sys, os

out = sys.argv[1]

def write(name, verts, faces):
    with open(os.path.join(out, name + ".obj"), "w") as f:
        f.write(f"# {name}: {len(verts)} vertices, {len(faces)} triangles\n")
        for v in verts:
            f.write("v %.6f %.6f %.6f\n" % v)
        for a, b, c in faces:
            f.write(f"f {a + 1} {b + 1} {c + 1}\n")

def sphere(r, nu, nv):
    verts = [(0.0, 0.0, r)]
    for j in range(1, nv):
        t = math.pi * j / nv
        for i in range(nu):
            p = 2 * math.pi * i / nu
            verts.append((r * math.sin(t) * math.cos(p), r * math.sin(t) * math.sin(p), r * math.cos(t)))
    verts.append((0.0, 0.0, -r))
    ring = lambda j, i: 1 + (j - 1) * nu + i % nu
    south = len(verts) - 1
    faces = [(0, ring(1, i), ring(1, i + 1)) for i in range(nu)]
    for j in range(1, nv - 1):
        for i in range(nu):
            a, b, c, d = ring(j, i), ring(j + 1, i), ring(j + 1, i + 1), ring(j, i + 1)
            faces += [(a, b, c), (a, c, d)]
    faces += [(ring(nv - 1, i), south, ring(nv - 1, i + 1)) for i in range(nu)]
    return verts, faces

def torus(big, small, nu, nv):
    verts = []
    for i in range(nu):
        u = 2 * math.pi * i / nu
        for j in range(nv):
            v = 2 * math.pi * j / nv
            w = big + small * math.cos(v)
            verts.append((w * math.cos(u), w * math.sin(u), small * math.sin(v)))
    idx = lambda i, j: (i % nu) * nv + j % nv
    faces = []
    for i in range(nu):
        for j in range(nv):
            a, b, c, d = idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1)
            faces += [(a, b, c), (a, c, d)]
    return verts, faces

def box(sx, sy, sz, n):
    # A closed box, each side an n x n grid, vertices shared along the edges.
    verts, index, faces = [], {}, []
    def vert(p):
        key = tuple(round(c, 9) for c in p)
        if key not in index:
            index[key] = len(verts)
            verts.append(p)
        return index[key]
    half = (sx / 2, sy / 2, sz / 2)
    for axis in range(3):
        for sign in (-1, 1):
            a1, a2 = [k for k in range(3) if k != axis]
            grid = {}
            for i in range(n + 1):
                for j in range(n + 1):
                    p = [0.0, 0.0, 0.0]
                    p[axis] = sign * half[axis]
                    p[a1] = -half[a1] + 2 * half[a1] * i / n
                    p[a2] = -half[a2] + 2 * half[a2] * j / n
                    grid[i, j] = vert(tuple(p))
            for i in range(n):
                for j in range(n):
                    a, b, c, d = grid[i, j], grid[i + 1, j], grid[i + 1, j + 1], grid[i, j + 1]
                    # Outward normals: flip the winding on one side of each axis.
                    if (sign > 0) == (axis == 1):
                        faces += [(a, c, b), (a, d, c)]
                    else:
                        faces += [(a, b, c), (a, c, d)]
    return verts, faces

write("sphere_small", *sphere(0.5, 16, 12))
write("sphere_big", *sphere(2.0, 40, 30))
write("torus_thin", *torus(1.0, 0.2, 48, 16))
write("torus_fat", *torus(1.0, 0.5, 32, 24))
write("box_cube", *box(1.0, 1.0, 1.0, 8))
write("box_slab", *box(3.0, 1.0, 0.3, 12))
EOF
ITEMS=(sphere_small sphere_big torus_thin torus_fat box_cube box_slab)
{
  echo "# tests/slurm/run_slurm_test.sh: 6 meshes, paths relative to this file"
  echo
  for name in "${ITEMS[@]}"; do echo "${name}.obj"; done
} > "${T}/data/manifest.txt"
for name in "${ITEMS[@]}"; do
  [[ -s "${T}/data/${name}.obj" ]] || fail "mesh ${name}.obj was not written"
  echo "   $(head -n 1 "${T}/data/${name}.obj")"
done

# --- submit: the array, then the summary after it
BATCH_ARGS="--jobs 1 --item-timeout 600"
for s in "${FAST_SETS[@]}"; do BATCH_ARGS+=" --set ${s}"; done
CPU_ARGS=()
((CPUS >= 2)) || CPU_ARGS=(--cpus-per-task="${CPUS}")

cd "${T}/work"
submit_array() { # $1: a tag for the output files; prints the job id
  MANIFEST="${T}/data/manifest.txt" OUT="${T}/out" SHARDS="${SHARDS}" NUVO="${NUVO}" NUVO_BATCH_ARGS="${BATCH_ARGS}" \
    sbatch --parsable --array=0-$((SHARDS - 1)) ${CPU_ARGS[@]+"${CPU_ARGS[@]}"} \
    --output="${T}/slurm/$1-%A_%a.out" "${REPO}/deploy/slurm/nuvo-batch.sbatch"
}
wait_for() { # job ids...; fails after TIMEOUT seconds
  local ids last="" now start=$SECONDS
  ids="$(IFS=,; echo "$*")"
  while true; do
    now="$(squeue -h -j "${ids}" -o '%.12i %.9P %.14j %.2t %.8M %R' 2> /dev/null || true)"
    if [[ "${now}" != "${last}" && -n "${now}" ]]; then echo "-- squeue at +$((SECONDS - start)) s:"; echo "${now}"; fi
    last="${now}"
    [[ -z "${now}" ]] && break
    ((SECONDS - start < TIMEOUT)) || fail "jobs ${ids} not finished after ${TIMEOUT} s"
    case "$(sinfo -h -n "${NODE}" -o %t)" in
      down* | drain* | fail*) fail "node ${NODE} went $(sinfo -h -n "${NODE}" -o %t): $(sinfo -h -R)" ;;
    esac
    sleep 2
  done
}

log "sbatch --array=0-$((SHARDS - 1)) deploy/slurm/nuvo-batch.sbatch  (NUVO_BATCH_ARGS=${BATCH_ARGS})"
t0="$(date +%s.%N)"
ARRAY="$(submit_array nuvo-batch)" || fail "sbatch of the array failed"
ARRAY="${ARRAY%%;*}"
JOBS+=("${ARRAY}")
SUMMARY="$(OUT="${T}/out" NUVO="${NUVO}" sbatch --parsable --dependency="afterany:${ARRAY}" \
  --output="${T}/slurm/nuvo-summary-%j.out" "${REPO}/deploy/slurm/nuvo-summary.sbatch")" || fail "sbatch of the summary failed"
SUMMARY="${SUMMARY%%;*}"
JOBS+=("${SUMMARY}")
echo "   array job ${ARRAY}, summary job ${SUMMARY}"
wait_for "${ARRAY}"
t1="$(date +%s.%N)"
wait_for "${SUMMARY}"
ARRAY_SECONDS="$(python3 -c "print(f'{${t1} - ${t0}:.1f}')")"
log "the array ended ${ARRAY_SECONDS} s after sbatch"

log "jobcomp records (JobCompType=jobcomp/filetxt; there is no accounting database for sacct)"
sed -E 's/^(JobId=[^ ]+).*(JobState=[^ ]+).*(StartTime=[^ ]+ EndTime=[^ ]+).*(ArrayJobId=[^ ]+ ArrayTaskId=[^ ]+).*(ExitCode=[^ ]+).*/\1 \4 \2 \5 \3/' \
  "${T}/log/jobcomp.txt"
for ((i = 0; i < SHARDS; i++)); do
  echo "-- ${T}/slurm/nuvo-batch-${ARRAY}_${i}.out:"
  sed 's/^/   /' "${T}/slurm/nuvo-batch-${ARRAY}_${i}.out" || fail "no Slurm output for task ${i}"
done

# --- the checks
log "checks"
python3 - "${T}/out" "${SHARDS}" "${ITEMS[@]}" << 'EOF' || fail "the item records are wrong (above)"
import json, os, re, sys
out, shards, names = sys.argv[1], int(sys.argv[2]), sys.argv[3:]
bad = []
for i, name in enumerate(names):
    path = os.path.join(out, name, "batch.json")
    try:
        rec = json.load(open(path))
    except Exception as e:
        bad.append(f"{name}: no readable batch.json ({e})")
        continue
    m = re.match(r"\s*(\d+)\s*/\s*(\d+)", str(rec.get("shard", "")))
    shard = (int(m.group(1)), int(m.group(2))) if m else None
    print(f"   {name:13} item {i}: status={rec.get('status')!r} shard={rec.get('shard')!r} "
          f"host={rec.get('host')!r} seconds={rec.get('seconds')}")
    if rec.get("status") != "done":
        bad.append(f"{name}: status {rec.get('status')!r}, error {rec.get('error')!r}")
        try:
            tail = open(os.path.join(out, name, "batch.log"), errors="replace").read().splitlines()[-10:]
            print(f"   -- last lines of {name}/batch.log:", *("      " + l for l in tail), sep="\n")
        except OSError:
            pass
    if shard != (i % shards, shards):
        bad.append(f"{name}: run by shard {rec.get('shard')!r}, but item {i} belongs to shard {i % shards}/{shards}")
    if "training.steps=12" not in rec.get("set", []):
        bad.append(f"{name}: ran without NUVO_BATCH_ARGS' --set training.steps=12 (set: {rec.get('set')!r})")
    if not os.path.isfile(os.path.join(out, name, "batch.log")):
        bad.append(f"{name}: no batch.log")
extra = sorted(d for d in os.listdir(out) if os.path.isdir(os.path.join(out, d)) and d not in names)
if extra:
    bad.append(f"folders in the batch folder that are no item: {extra}")
for b in bad:
    print("   BAD:", b)
sys.exit(1 if bad else 0)
EOF
echo "   ok: 6 items done with the --set of NUVO_BATCH_ARGS, each by the one shard i mod ${SHARDS} that owns it (batch.json 'shard')"
for ((i = 0; i < SHARDS; i++)); do
  grep -q "ArrayJobId=${ARRAY} ArrayTaskId=${i} .*JobState=COMPLETED\|JobState=COMPLETED.* ArrayJobId=${ARRAY} ArrayTaskId=${i} " "${T}/log/jobcomp.txt" \
    || fail "array task ${ARRAY}_${i} did not end COMPLETED: $(grep "ArrayJobId=${ARRAY} ArrayTaskId=${i} " "${T}/log/jobcomp.txt" || echo 'no record')"
done
grep -q "^JobId=${SUMMARY} .*JobState=COMPLETED" "${T}/log/jobcomp.txt" || fail "summary job ${SUMMARY} did not end COMPLETED"
echo "   ok: the 3 array tasks and the summary job ended COMPLETED (exit 0)"

# Each item by exactly one task: an item's name may appear in the output of its own task only.
for i in "${!ITEMS[@]}"; do
  name="${ITEMS[$i]}"
  in_tasks=()
  for ((s = 0; s < SHARDS; s++)); do
    grep -qw -- "${name}" "${T}/slurm/nuvo-batch-${ARRAY}_${s}.out" && in_tasks+=("${s}")
  done
  if ((${#in_tasks[@]} > 1)) || { ((${#in_tasks[@]} == 1)) && [[ "${in_tasks[0]}" != $((i % SHARDS)) ]]; }; then
    fail "${name} (item ${i}, shard $((i % SHARDS))) appears in the Slurm output of tasks ${in_tasks[*]}"
  fi
done
echo "   ok: no item named in the Slurm output of another task"

SUMMARY_OUT="${T}/slurm/nuvo-summary-${SUMMARY}.out"
echo "-- ${SUMMARY_OUT}:"
sed 's/^/   /' "${SUMMARY_OUT}"
[[ -s "${T}/out/summary.md" ]] || fail "the summary job wrote no ${T}/out/summary.md"
[[ -s "${T}/out/summary.csv" ]] || fail "the summary job wrote no ${T}/out/summary.csv"
check_summary() { # $1: summary.csv, $2: the printed Markdown, $3: who printed it
  python3 - "$1" "$2" "$3" "${ITEMS[@]}" << 'EOF'
import csv, sys
rows = list(csv.DictReader(open(sys.argv[1], newline="")))
md = open(sys.argv[2]).read()
who = sys.argv[3]
names = sys.argv[4:]
got = [(r.get("item", r.get("name")), r.get("status")) for r in rows]  # the first column is `item`
if got != [(n, "done") for n in names]:
    sys.exit(f"summary.csv rows (name, status) are {got}, expected the 6 items in manifest order, all done")
md_done = [l for l in md.splitlines() if l.startswith("|") and any(f" {n} " in l for n in names) and " done " in l]
if len(md_done) != len(names):
    sys.exit(f"the printed Markdown has {len(md_done)} rows of done items, not {len(names)}")
print(f"   ok ({who}): summary.csv has {len(rows)} rows, all done, in manifest order; the printed table has {len(md_done)} done rows")
EOF
}
check_summary "${T}/out/summary.csv" "${SUMMARY_OUT}" "summary job" || fail "the summary job's summary is wrong"
"${NUVO}" batch --summary "${T}/out" > "${T}/summary-direct.md" || fail "nuvo batch --summary ${T}/out exited $?"
check_summary "${T}/out/summary.csv" "${T}/summary-direct.md" "nuvo batch --summary, run directly" || fail "nuvo batch --summary (run directly) is wrong"

# --- resubmitting the array redoes nothing
log "resubmitting the same array: every item is done, so none may run again"
before="$(cd "${T}/out" && for n in "${ITEMS[@]}"; do stat -c '%n %Y.%y' "${n}/batch.json"; cksum < "${n}/batch.json"; done)"
AGAIN="$(submit_array nuvo-batch-again)" || fail "sbatch of the second array failed"
AGAIN="${AGAIN%%;*}"
JOBS+=("${AGAIN}")
wait_for "${AGAIN}"
after="$(cd "${T}/out" && for n in "${ITEMS[@]}"; do stat -c '%n %Y.%y' "${n}/batch.json"; cksum < "${n}/batch.json"; done)"
for ((i = 0; i < SHARDS; i++)); do
  grep -q "ArrayJobId=${AGAIN} ArrayTaskId=${i} .*JobState=COMPLETED\|JobState=COMPLETED.* ArrayJobId=${AGAIN} ArrayTaskId=${i} " "${T}/log/jobcomp.txt" \
    || fail "second array's task ${AGAIN}_${i} did not end COMPLETED: $(grep "ArrayJobId=${AGAIN} ArrayTaskId=${i} " "${T}/log/jobcomp.txt" || echo 'no record')"
  echo "-- ${T}/slurm/nuvo-batch-again-${AGAIN}_${i}.out:"
  sed 's/^/   /' "${T}/slurm/nuvo-batch-again-${AGAIN}_${i}.out"
done
[[ "${before}" == "${after}" ]] || fail "the second array rewrote batch.json files: before/after differ"
echo "   ok: the second array ended COMPLETED and left every batch.json as it was"

REASON="Slurm $(sinfo -V | awk '{print $2}'): array ${ARRAY} of ${SHARDS} tasks ran the 6 items (each by its own shard, all done) in ${ARRAY_SECONDS} s from sbatch; summary job ${SUMMARY} listed 6 done rows; a resubmission (${AGAIN}) redid nothing"
exit 0
