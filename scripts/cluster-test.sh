#!/usr/bin/env bash
# `make cluster-test`: the pipeline as a SLURM job graph on a REAL one-node
# cluster on this machine, compared with a single-process `run`.
#
# - Installs Debian's slurm-wlm and munge if missing (no systemd is used).
# - Starts munged, slurmctld and slurmd from a temporary folder, inside a
#   private network namespace (unshare -n) that holds only a loopback
#   interface: nothing listens beyond this machine, and every daemon is
#   stopped at the end, whatever happens.
# - Submits the demo exemplar with a tiny profile through `shapeshifter slurm`
#   (encode, a training array of one task per level, sampling and meshing
#   arrays of shards, evaluation), waits, and checks that every job completed.
# - Runs the same exemplar, profile and seed as one `shapeshifter run`, and
#   checks: the same level data (bit for bit), the same trained weights, the
#   same eval.json figures.
# - Kills a training task mid-way (`scontrol requeue`), and checks that the
#   requeued task resumed from its checkpoint and finished.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$(pwd)

if [ "${SS_IN_NETNS:-}" != 1 ]; then
  missing=()
  for p in slurm-wlm munge; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
  if ((${#missing[@]})); then
    echo "cluster-test: installing ${missing[*]}" >&2
    SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO=sudo
    $SUDO apt-get update -q
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -q --no-install-recommends "${missing[@]}"
  fi
  [ -x target/release/shapeshifter ] || { echo "cluster-test: build first (make build)" >&2; exit 1; }
  [ -x target/release/examples/demo_exemplar ] || cargo build --release --example demo_exemplar
  # Everything below runs in a private network namespace (root needed for
  # slurmd anyway).
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo -E"
  exec $SUDO env SS_IN_NETNS=1 unshare --net "$0" "$@"
fi

ip link set lo up
# glibc's getaddrinfo (AI_ADDRCONFIG, as Slurm calls it) resolves nothing, not
# even 127.0.0.1, on a host with no non-loopback address: a veth pair with a
# private address, both ends inside this namespace, reachable from nowhere else.
ip link add ssv0 type veth peer name ssv1
ip addr add 10.254.254.1/32 dev ssv0
ip link set ssv0 up
ip link set ssv1 up
BIN=$ROOT/target/release/shapeshifter
WORK=$(mktemp -d /tmp/ss-cluster.XXXXXX)
chmod 755 "$WORK"
export SLURM_CONF=$WORK/etc/slurm.conf
PASS=0
stop() {
  local rc=$?
  for pid in "$WORK"/run/*.pid; do
    [ -f "$pid" ] && kill "$(cat "$pid")" 2>/dev/null || true
  done
  sleep 1
  for pid in "$WORK"/run/*.pid; do
    [ -f "$pid" ] && kill -9 "$(cat "$pid")" 2>/dev/null || true
  done
  if [ "$PASS" != 1 ]; then
    echo "cluster-test: FAILED (rc $rc); daemon logs:" >&2
    tail -n 30 "$WORK"/log/*.log >&2 2>/dev/null || true
    tail -n 30 "$WORK"/cluster/slurm/logs/* >&2 2>/dev/null || true
  fi
  [ "${KEEP:-0}" = 1 ] && echo "cluster-test: kept $WORK" >&2 || rm -rf "$WORK"
}
trap stop EXIT
mkdir -p "$WORK"/{etc,run,log,state,spool,munge}
chmod 755 "$WORK/munge"

# --- munge: its own key and socket --------------------------------------------
dd if=/dev/urandom of="$WORK/munge/munge.key" bs=1024 count=1 status=none
chmod 400 "$WORK/munge/munge.key"
munged --force --key-file="$WORK/munge/munge.key" --socket="$WORK/munge/munge.socket" \
  --pid-file="$WORK/run/munged.pid" --log-file="$WORK/log/munged.log" --seed-file="$WORK/munge/seed"

# --- slurm: one node, two cores, bound to the namespace's loopback ------------
cat > "$SLURM_CONF" <<EOF
ClusterName=shapeshifter-test
SlurmctldHost=localhost(127.0.0.1)
SlurmctldPort=16817
SlurmdPort=16818
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$WORK/munge/munge.socket
StateSaveLocation=$WORK/state
SlurmdSpoolDir=$WORK/spool
SlurmctldPidFile=$WORK/run/slurmctld.pid
SlurmdPidFile=$WORK/run/slurmd.pid
SlurmctldLogFile=$WORK/log/slurmctld.log
SlurmdLogFile=$WORK/log/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/filetxt
JobCompLoc=$WORK/log/jobcomp.txt
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
MpiDefault=none
ReturnToService=2
MinJobAge=3600
NodeName=localhost NodeAddr=127.0.0.1 CPUs=2 RealMemory=8000 State=UNKNOWN
PartitionName=debug Nodes=localhost Default=YES MaxTime=INFINITE State=UP
EOF
slurmctld -i
slurmd -N localhost
for _ in $(seq 60); do
  sinfo -h -o '%T' 2>/dev/null | grep -qE '^(idle|mixed)' && break
  sleep 1
done
sinfo -h -o '%T' | grep -qE '^(idle|mixed)' || { echo "cluster-test: the node did not come up" >&2; exit 1; }
echo "cluster-test: one-node cluster up: $(sinfo -h -o '%N %c CPUs %m MB %T')"

"$ROOT/target/release/examples/demo_exemplar" --out "$WORK/mesh" > /dev/null
MESH=$WORK/mesh/demo_tower.ply
# Three levels: networks at 16 and 32, detail transfer at 64 (the cpu profile's
# split at a tenth of the cost), so the sharded transfer is compared too.
TINY=(--set encode.sampling_resolution=256 --set encode.finest_resolution=64 --set transfer.from_resolution=64
      --set train.level0_iterations=60 --set train.upper_iterations=30 --set train.upsampler_iterations=30
      --set cluster.variants_per_job=2 --set cluster.train_mem_gb=1 --set cluster.sample_mem_gb=1
      --set cluster.mesh_mem_gb=1 --set cluster.eval_mem_gb=1 --set cluster.encode_mem_gb=1
      --set cluster.train_minutes=10 --set cluster.job_minutes=10)
N=5

# Wait until no job of ours is pending or running (at most $1 seconds).
wait_idle() {
  local t=0
  while [ -n "$(squeue -h -o %i)" ]; do
    sleep 2; t=$((t + 2))
    [ "$t" -lt "$1" ] || { echo "cluster-test: jobs still queued after $1 s:" >&2; squeue >&2; return 1; }
  done
}

# --- 1. the job graph ----------------------------------------------------------
start=$(date +%s)
"$BIN" -q slurm "$MESH" -o "$WORK/cluster" -n $N --seed 3 "${TINY[@]}" | tee "$WORK/ids.txt"
squeue -o '%.12i %.16j %.8T %.10M %R' | sed 's/^/  squeue: /'
wait_idle 900
echo "cluster-test: job graph finished in $(( $(date +%s) - start )) s"
fail=0
while read -r stage id; do
  # Every task of every job (arrays list one line per task).
  while read -r line; do
    state=$(sed -n 's/.*JobState=\([A-Z_]*\).*/\1/p' <<<"$line")
    name=$(sed -n 's/.*JobName=\([^ ]*\).*/\1/p' <<<"$line")
    jid=$(sed -n 's/^JobId=\([0-9]*\).*/\1/p' <<<"$line")
    task=$(sed -n 's/.*ArrayTaskId=\([0-9]*\).*/\1/p' <<<"$line")
    run=$(sed -n 's/.*RunTime=\([0-9:-]*\).*/\1/p' <<<"$line")
    code=$(sed -n 's/.* ExitCode=\([0-9:]*\).*/\1/p' <<<"$line")
    printf '  job %-8s %-22s task %-2s %-10s elapsed %s exit %s\n' "$jid" "$name" "${task:--}" "$state" "$run" "$code"
    [ "$state" = COMPLETED ] || fail=1
  done < <(scontrol -o show job "$id")
done < "$WORK/ids.txt"
[ "$fail" = 0 ] || { echo "cluster-test: a job did not complete" >&2; exit 1; }
echo "cluster-test: every job COMPLETED"

# --- 2. the same run in one process --------------------------------------------
"$BIN" -q run "$MESH" -o "$WORK/single" -n $N --seed 3 "${TINY[@]}" > "$WORK/single.log"
"$BIN" compare "$WORK/single" "$WORK/cluster" | sed 's/^/  compare: /'
"$BIN" compare "$WORK/single" "$WORK/cluster" > /dev/null || { echo "cluster-test: level data differ" >&2; exit 1; }
(cd "$WORK/single/models" && sha256sum ./*.safetensors) > "$WORK/single.sha"
(cd "$WORK/cluster/models" && sha256sum -c --quiet "$WORK/single.sha") || { echo "cluster-test: trained weights differ" >&2; exit 1; }
echo "  weights: $(wc -l < "$WORK/single.sha") checkpoints identical (sha256)"
python3 - "$WORK/single/eval.json" "$WORK/cluster/eval.json" <<'EOF'
import json, sys
a, b = (json.load(open(p)) for p in sys.argv[1:3])
keys = ("variants", "mean", "diversity", "set_coverage")
diff = [k for k in keys if a[k] != b[k]]
if diff:
    sys.exit(f"cluster-test: eval.json differs in {diff}")
print(f"  eval: identical ({len(a['variants'])} variants, diversity {a['diversity']:.4f}, LP-IoU {a['mean']['lp_iou']:.3f})")
EOF

# --- 3. a training task killed mid-way resumes from its checkpoint --------------
# Level 0 long enough to be killed mid-way (the requeue comes at its first
# checkpoint, 0.6 s in) and short enough to finish within the wait below on a
# CPU without AVX-512, where a level-0 step of the cpu profile took 0.88 s
# (2026-12-03; 4000 steps did not finish in 900 s there).
LEVEL0_STEPS=300
LONG=(--set encode.sampling_resolution=128 --set encode.finest_resolution=32 --set train.level0_iterations=$LEVEL0_STEPS --set train.upper_iterations=30 --set train.upsampler_iterations=30
      --set train.checkpoint_minutes=0.01 --set cluster.train_mem_gb=1 --set cluster.encode_mem_gb=1)
"$BIN" -q stage encode "$MESH" -o "$WORK/requeue" "${LONG[@]}" > /dev/null
"$BIN" -q slurm "$MESH" -o "$WORK/requeue" -n 1 "${LONG[@]}" --dry-run > /dev/null
train_id=$(sbatch --parsable "$WORK/requeue/slurm/train.sbatch"); train_id=${train_id%%;*}
state=$WORK/requeue/models/level_0_state.json
for _ in $(seq 300); do
  [ -f "$state" ] && python3 -c "import json,sys; sys.exit(0 if json.load(open('$state'))['diffusion_steps'] > 0 else 1)" && break
  sleep 0.5
done
before=$(python3 -c "import json; print(json.load(open('$state'))['diffusion_steps'])")
scontrol requeue "${train_id}_0"
# Slurm holds a requeued job for about two minutes before it may start again;
# a test need not wait for that.
sleep 1
scontrol update JobId="${train_id}_0" StartTime=now 2>/dev/null || true
echo "  requeue: level-0 task killed and requeued once its checkpoints had reached step $before"
wait_idle 900
log=$(ls "$WORK"/requeue/slurm/logs/ss-train-*_0.out)
grep -m1 "resuming at upsampler step" "$log" | sed 's/^/  requeue: /' \
  || { echo "cluster-test: the requeued task did not resume" >&2; exit 1; }
python3 - "$state" "$LEVEL0_STEPS" <<'EOF'
import json, sys
s = json.load(open(sys.argv[1]))
if not (s["finished"] and s["diffusion_steps"] == int(sys.argv[2])):
    sys.exit(f"cluster-test: after the requeue level 0 is at {s['diffusion_steps']} steps, finished={s['finished']}")
print(f"  requeue: level 0 finished all {s['diffusion_steps']} steps after the resume")
EOF
echo "cluster-test: jobs recorded by slurm (jobcomp):"
sed 's/^/  /' "$WORK/log/jobcomp.txt" | cut -c1-220 | tail -n 30
PASS=1
echo "cluster-test: PASS"
