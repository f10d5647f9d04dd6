#!/usr/bin/env bash
# A sharded build on a real scheduler: a single-node Slurm (munged, slurmctld, slurmd on
# localhost, as root, without systemd) runs the base build (`hdov build --no-visibility`: tree,
# LODs, catalog) as one job, `hdov build --shard $SLURM_ARRAY_TASK_ID/N --base BASE` as an array
# job after it (afterok; each shard keeps only its cells' V-data, measured against the base's
# tree and LODs), and `hdov merge BASE SHARDS…` as a job after both; one task is cancelled
# mid-build (its transaction open) and requeued; it must run again to the end, leave nothing of
# its killed run behind, and the merged database must equal a
# whole build, every data file byte for byte. Prints the wall times and the bytes the shards
# and the base wrote.
#
#   tools/slurm/test-local.sh [HDOV_BINARY] [SCALE] [SHARDS]     (defaults: target/release/hdov small 4)
#
# HDOV_SLURM_DEBUG=1 prints the queue every 5 s while the jobs run.
#
# Installs Debian's slurm-wlm and munge when missing. If a daemon cannot start it prints why
# (its log) and exits 1: it never skips. Everything it starts is stopped on exit, and all it
# writes lies in one temporary folder.
set -euo pipefail

HDOV=$(realpath "${1:-target/release/hdov}")
SCALE=${2:-small}
N=${3:-4}
[ -x "$HDOV" ] || { echo "slurm test: $HDOV is not an executable (cargo build --release first)"; exit 1; }
[ "$(id -u)" -eq 0 ] || { echo "slurm test: the daemons are started as root; run it as root"; exit 1; }

if ! command -v slurmctld >/dev/null 2>&1 || ! command -v munged >/dev/null 2>&1; then
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq
  apt-get install -y -qq slurm-wlm munge >/dev/null
fi

WORK=$(mktemp -d /tmp/hdov-slurm.XXXXXX)
HOST=$(hostname -s)
CPUS=$(nproc)
MEM=$(( $(awk '/MemTotal/ {print $2}' /proc/meminfo) / 1024 * 9 / 10 ))
PIDS=()

stop() {
  for p in "${PIDS[@]}"; do kill "$p" 2>/dev/null || true; done
  sleep 1
  for p in "${PIDS[@]}"; do kill -9 "$p" 2>/dev/null || true; done
  rm -rf "$WORK"
}
trap stop EXIT

fail() {
  echo "slurm test: $1"
  for log in "$WORK"/log/*.log; do
    [ -f "$log" ] && { echo "--- $(basename "$log")"; tail -n 30 "$log"; }
  done
  exit 1
}

mkdir -p "$WORK"/{log,state,spool,munge,run,data}
chmod 700 "$WORK/munge"

# munge: its own key, socket and pid files in $WORK, so that nothing of the host's changes.
dd if=/dev/urandom of="$WORK/munge/munge.key" bs=1024 count=1 status=none
chmod 400 "$WORK/munge/munge.key"
MUNGE_SOCKET="$WORK/run/munge.socket"
munged --force --foreground --key-file="$WORK/munge/munge.key" --socket="$MUNGE_SOCKET" \
  --pid-file="$WORK/run/munged.pid" --log-file="$WORK/log/munged.log" --seed-file="$WORK/munge/seed" \
  >"$WORK/log/munged.out.log" 2>&1 &
PIDS+=($!)
for _ in $(seq 50); do [ -S "$MUNGE_SOCKET" ] && break; sleep 0.1; done
[ -S "$MUNGE_SOCKET" ] || fail "munged did not start"

# Two free ports for slurmctld and slurmd (another Slurm may run on the standard ones).
free_port() {
  local p
  for p in $(seq "$1" $(($1 + 200))); do
    (exec 3<>"/dev/tcp/127.0.0.1/$p") 2>/dev/null || { echo "$p"; return; }
  done
  fail "no free port from $1"
}
CTLD_PORT=$(free_port 16817)
SLURMD_PORT=$(free_port $((CTLD_PORT + 1)))

# slurm.conf: one node, no accounting, no cgroups (linuxproc tracking, no task plugin), root.
export SLURM_CONF="$WORK/slurm.conf"
cat >"$SLURM_CONF" <<EOF
ClusterName=hdov
SlurmctldHost=$HOST
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
AuthInfo=socket=$MUNGE_SOCKET
CredType=cred/munge
SlurmctldPort=$CTLD_PORT
SlurmdPort=$SLURMD_PORT
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
SchedulerType=sched/backfill
SchedulerParameters=bf_interval=1
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
MpiDefault=none
ReturnToService=2
SlurmdTimeout=60
NodeName=$HOST CPUs=$CPUS RealMemory=$MEM State=UNKNOWN
PartitionName=local Nodes=$HOST Default=YES MaxTime=INFINITE State=UP AllowAccounts=ALL
EOF
cat >"$WORK/cgroup.conf" <<EOF
IgnoreSystemd=yes
EOF

slurmctld -D -i -f "$SLURM_CONF" >"$WORK/log/slurmctld.out.log" 2>&1 &
PIDS+=($!)
slurmd -D -f "$SLURM_CONF" >"$WORK/log/slurmd.out.log" 2>&1 &
PIDS+=($!)
up=""
for _ in $(seq 100); do
  if sinfo -h -o '%T' 2>/dev/null | grep -Eq '^(idle|mixed|allocated)'; then up=1; break; fi
  sleep 0.2
done
[ -n "$up" ] || fail "the node never came up (sinfo: $(sinfo -h 2>&1 | head -1))"
echo "slurm: $(sinfo -h -o '%P %D nodes, %c CPUs, %T')"

# The scene, and the whole build to compare with.
"$HDOV" generate city --scale "$SCALE" --out "$WORK/data/city" >/dev/null
SCENE="$WORK/data/city/city.json"
t0=$(date +%s.%N)
"$HDOV" build "$SCENE" --out "$WORK/data/whole.hdov" --backend cpu >/dev/null
t1=$(date +%s.%N)

# The array job, one task per shard; each run of a task leaves a line in runs-ID first, so that
# the requeued one can be seen to have run again.
cat >"$WORK/shard.sh" <<EOF
#!/bin/bash
echo "\$SLURM_JOB_ID \$(date +%s.%N)" >>"$WORK/log/runs-\$SLURM_ARRAY_TASK_ID"
exec "$HDOV" build "$SCENE" --out "$WORK/data/shard\$SLURM_ARRAY_TASK_ID.hdov" \\
  --shard \$SLURM_ARRAY_TASK_ID/$N --base "$WORK/data/base.hdov" --backend cpu --force
EOF
cat >"$WORK/base.sh" <<EOF
#!/bin/bash
exec "$HDOV" build "$SCENE" --out "$WORK/data/base.hdov" --backend cpu --no-visibility
EOF
cat >"$WORK/merge.sh" <<EOF
#!/bin/bash
exec "$HDOV" merge "$WORK/data/base.hdov" $(for i in $(seq 0 $((N - 1))); do printf '%s ' "$WORK/data/shard$i.hdov"; done) --out "$WORK/data/merged.hdov"
EOF
chmod +x "$WORK/base.sh" "$WORK/shard.sh" "$WORK/merge.sh"
t2=$(date +%s.%N)
BASE=$(sbatch --parsable -c 1 -o "$WORK/log/base.log" "$WORK/base.sh") || fail "sbatch of the base build failed"
ARRAY=$(sbatch --parsable --requeue --array=0-$((N - 1)) -c 1 --dependency=afterok:"$BASE" \
  -o "$WORK/log/shard-%a.log" "$WORK/shard.sh") \
  || fail "sbatch of the array job failed"
MERGE=$(sbatch --parsable --dependency=afterok:"$BASE":"$ARRAY" -o "$WORK/log/merge.log" "$WORK/merge.sh") \
  || fail "sbatch of the merge job failed"
echo "slurm: base job $BASE, array job $ARRAY ($N shards) after it, merge job $MERGE after both"

# Cancel one task while its hdov builds its database (its `.shardI.hdov.tmp-PID` directory open,
# nothing yet at the target) and put it back in the queue.
VICTIM=$((N - 1))
writing=""
for _ in $(seq 6000); do
  state=$(squeue -h -j "${ARRAY}_${VICTIM}" -o '%T' 2>/dev/null || true)
  if [ "$state" = RUNNING ] && [ ! -e "$WORK/data/shard$VICTIM.hdov" ]; then
    writing=$(find "$WORK/data" -maxdepth 1 -name ".shard$VICTIM.hdov.tmp-*" -type d 2>/dev/null | head -1)
    [ -n "$writing" ] && break
  fi
  [ -e "$WORK/data/shard$VICTIM.hdov" ] && fail "task $VICTIM finished before it could be cancelled while building"
  sleep 0.02
done
[ -n "$writing" ] || fail "task $VICTIM was never seen writing (state '$state')"
scontrol requeue "${ARRAY}_${VICTIM}" || fail "requeue of task $VICTIM failed"
[ ! -e "$WORK/data/shard$VICTIM.hdov" ] || fail "task $VICTIM had finished when it was cancelled"
echo "slurm: task $VICTIM cancelled while building in $(basename "$writing")"
# Slurm holds a requeued batch job back for two minutes (reason BeginTime); once it is pending
# again, let it start now.
for _ in $(seq 100); do
  [ "$(squeue -h -j "${ARRAY}_${VICTIM}" -o '%T %r' 2>/dev/null)" = "PENDING BeginTime" ] && break
  sleep 0.1
done
# Release it only once the cancelled run's step daemon on the node has gone: a restart while
# slurmd is still tearing the old run down is killed ("Job credential revoked") and fails.
RAW=$(squeue -h -j "${ARRAY}_${VICTIM}" -o '%A')
for _ in $(seq 300); do
  pgrep -f "slurmstepd: \[$RAW\." >/dev/null || break
  sleep 0.1
done
! pgrep -f "slurmstepd: \[$RAW\." >/dev/null || fail "the cancelled run of task $VICTIM did not end"
# And only in a later second than the requeue: slurmd rejects a launch whose credential is not
# newer than the job's revocation (`cred->ctime <= j->revoked` in slurm_cred.c, both whole
# seconds), so a restart within the same second was killed ("Job credential revoked") even after
# the step daemon had gone (CI, 2026-12-02: released 0.1 s after the requeue).
sleep 2
scontrol update JobId="${ARRAY}_${VICTIM}" StartTime=now || fail "could not release the requeued task"
echo "slurm: task $VICTIM cancelled while running and requeued"

for i in $(seq 3000); do
  [ -z "$(squeue -h -j "$BASE,$ARRAY,$MERGE" 2>/dev/null)" ] && break
  # A job that failed leaves the merge waiting for ever: say so now, not after ten minutes.
  if squeue -h -j "$MERGE" -o '%r' 2>/dev/null | grep -q DependencyNeverSatisfied; then
    fail "a base or shard job failed: $(scontrol show job "$ARRAY" | grep -E 'ArrayTaskId|JobState' | tr -s ' ' | tr '\n' ' ')"
  fi
  [ -n "${HDOV_SLURM_DEBUG:-}" ] && [ $((i % 25)) -eq 0 ] && squeue -h -o '%i %T %r %S' | tr '\n' ';' && echo
  sleep 0.2
done
t3=$(date +%s.%N)
[ -z "$(squeue -h -j "$BASE,$ARRAY,$MERGE" 2>/dev/null)" ] || fail "jobs still queued after 10 minutes: $(squeue -h)"
[ -d "$WORK/data/merged.hdov" ] || fail "the merge job wrote no database: $(cat "$WORK/log/merge.log" 2>/dev/null)"
# The cancelled task ran again, to the end, and its first run's half-written directory is gone
# (the next build of the same target removes what a dead process left).
runs=$(grep -c . "$WORK/log/runs-$VICTIM" 2>/dev/null || echo 0)
[ "$runs" -ge 2 ] || fail "task $VICTIM ran $runs time(s); the requeued run never started"
[ -d "$WORK/data/shard$VICTIM.hdov" ] || fail "the requeued task $VICTIM wrote no database"
leftover=$(find "$WORK/data" -maxdepth 1 -name ".shard$VICTIM.hdov.*" | head -1)
[ -z "$leftover" ] || fail "the cancelled run of task $VICTIM left $leftover"
echo "slurm: task $VICTIM ran $runs times; its last run finished the shard"

# Every data file byte for byte; the manifests differ only in what the builds measured.
for f in "$WORK"/data/whole.hdov/*; do
  name=$(basename "$f")
  [ "$name" = manifest.json ] && continue
  cmp -s "$f" "$WORK/data/merged.hdov/$name" || fail "$name differs between the merged and the whole build"
done
[ "$(ls "$WORK/data/whole.hdov")" = "$(ls "$WORK/data/merged.hdov")" ] || fail "the databases hold different files"

printf 'slurm: merged database equals the whole build (%s files, byte for byte)\n' "$(ls "$WORK/data/whole.hdov" | wc -l)"
printf 'slurm: the %d shards wrote %s bytes in all, the base %s (the scene once)\n' "$N" \
  "$(du -cb "$WORK"/data/shard*.hdov | tail -1 | cut -f1)" "$(du -sb "$WORK/data/base.hdov" | cut -f1)"
printf 'slurm: whole build %.1f s; the base, %d shards through Slurm (one requeued) and the merge %.1f s (%s CPUs)\n' \
  "$(echo "$t1 - $t0" | bc)" "$N" "$(echo "$t3 - $t2" | bc)" "$CPUS"
echo "slurm: 1 passed, 0 failed"
