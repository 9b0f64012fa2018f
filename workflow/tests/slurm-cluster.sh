#!/usr/bin/env bash
# A one-node Slurm cluster on this machine, for testing the workflow's Slurm profile (Debian's
# slurmctld, slurmd, slurm-client and munge; scripts/setup-workflow.sh installs them). Everything
# lives in DIR: its own munge key and socket, state, spool, logs and free TCP ports, so it does
# not touch /etc/slurm, /etc/munge or a cluster already running here. Needs root (slurmd runs
# the jobs as the submitting user).
#
#   bash workflow/tests/slurm-cluster.sh start DIR   # prints the line below
#   export PATH=DIR/bin:$PATH SLURM_CONF=DIR/slurm.conf; sinfo; snakemake --profile workflow/profiles/slurm …
#   bash workflow/tests/slurm-cluster.sh stop DIR
#
# `start` waits until the node is idle and a job runs (srun hostname); on failure it prints the
# daemons' last log lines and exits non-zero.
set -euo pipefail

cmd=${1:-}
dir=${2:-}
[ -n "$cmd" ] && [ -n "$dir" ] || { echo "usage: $0 start|stop DIR" >&2; exit 2; }

stop() {
  for pid in "$dir/slurmd.pid" "$dir/slurmctld.pid" "$dir/munge/munged.pid"; do
    if [ -s "$pid" ]; then
      p=$(cat "$pid")
      kill "$p" 2>/dev/null || true
      for _ in $(seq 50); do kill -0 "$p" 2>/dev/null || break; sleep 0.1; done
      kill -9 "$p" 2>/dev/null || true
      rm -f "$pid"
    fi
  done
}

fail() {
  echo "slurm-cluster: $*" >&2
  for log in "$dir/munge/munged.log" "$dir/slurmctld.log" "$dir/slurmd.log"; do
    [ -f "$log" ] && { echo "--- $log (last lines)" >&2; tail -n 15 "$log" >&2; }
  done
  stop
  exit 1
}

if [ "$cmd" = stop ]; then
  stop
  exit 0
fi
[ "$cmd" = start ] || { echo "usage: $0 start|stop DIR" >&2; exit 2; }
[ "$(id -u)" -eq 0 ] || { echo "slurm-cluster: needs root (slurmd)" >&2; exit 1; }
for b in munged slurmctld slurmd sbatch srun squeue sinfo; do
  command -v "$b" >/dev/null || { echo "slurm-cluster: $b not found (bash scripts/setup-workflow.sh)" >&2; exit 1; }
done

mkdir -p "$dir"
dir=$(cd "$dir" && pwd)
mkdir -p "$dir/munge" "$dir/state" "$dir/spool"
chmod 700 "$dir/munge"

# munge: a fresh key, a private socket.
head -c 1024 /dev/urandom > "$dir/munge/munge.key"
chmod 400 "$dir/munge/munge.key"
sock="$dir/munge/munge.socket.2"
munged --force --socket="$sock" --key-file="$dir/munge/munge.key" \
  --pid-file="$dir/munge/munged.pid" --seed-file="$dir/munge/munged.seed" \
  --log-file="$dir/munge/munged.log" || fail "munged did not start"
for _ in $(seq 50); do [ -S "$sock" ] && break; sleep 0.1; done
[ -S "$sock" ] || fail "munged made no socket"
munge --socket="$sock" -n | unmunge --socket="$sock" >/dev/null || fail "munge round trip failed"

# Two free ports (the kernel picks them).
read -r ctld_port slurmd_port < <(python3 -c '
import socket
s = [socket.socket() for _ in range(2)]
for x in s: x.bind(("127.0.0.1", 0))
print(*[x.getsockname()[1] for x in s])')
host=$(hostname -s)
cpus=$(nproc)
# Half the machine's memory, so the workflow's requests (mem_mb) are checked against a real limit.
mem=$(awk '/MemTotal/ {printf "%d", $2 / 1024 / 2}' /proc/meminfo)

cat > "$dir/slurm.conf" <<EOF
ClusterName=herdfit-test
SlurmctldHost=$host(127.0.0.1)
SlurmctldPort=$ctld_port
SlurmdPort=$slurmd_port
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$sock
SlurmUser=root
SlurmdUser=root
StateSaveLocation=$dir/state
SlurmdSpoolDir=$dir/spool
SlurmctldPidFile=$dir/slurmctld.pid
SlurmdPidFile=$dir/slurmd.pid
SlurmctldLogFile=$dir/slurmctld.log
SlurmdLogFile=$dir/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
MpiDefault=none
ReturnToService=2
# Finished jobs stay visible to squeue for 10 min: the workflow's status checks use squeue here
# (there is no accounting database for sacct).
MinJobAge=600
SlurmctldTimeout=30
SlurmdTimeout=30
InactiveLimit=0
KillWait=5
NodeName=$host NodeAddr=127.0.0.1 CPUs=$cpus RealMemory=$mem State=UNKNOWN
PartitionName=herdfit Nodes=$host Default=YES MaxTime=INFINITE State=UP
EOF
export SLURM_CONF="$dir/slurm.conf"
# Client commands that find this cluster without SLURM_CONF: snakemake-executor-plugin-slurm-jobstep
# (0.6.1) drops every SLURM_* variable but a few before its srun inside a job, so SLURM_CONF does
# not reach it; a cluster configured in /etc/slurm or configless needs none of this.
mkdir -p "$dir/bin"
for b in srun sbatch squeue scancel sinfo scontrol sacct; do
  real=$(command -v "$b") || continue
  printf '#!/bin/sh\nSLURM_CONF=%s exec %s "$@"\n' "$SLURM_CONF" "$real" > "$dir/bin/$b"
  chmod +x "$dir/bin/$b"
done

slurmctld -f "$SLURM_CONF" || fail "slurmctld did not start"
slurmd -f "$SLURM_CONF" || fail "slurmd did not start"

state=""
for _ in $(seq 150); do
  state=$(sinfo -h -N -o '%t' 2>/dev/null | head -n1 || true)
  [ "$state" = idle ] && break
  sleep 0.2
done
[ "$state" = idle ] || fail "the node is '${state:-unreachable}', not idle, after 30 s"
out=$(timeout 60 srun -N1 -n1 -t 1 hostname 2>&1) || fail "srun hostname failed: $out"
echo "slurm-cluster: node $host ($cpus CPUs, $mem MB) idle, srun ran on $out"
echo "export PATH=$dir/bin:\$PATH SLURM_CONF=$SLURM_CONF"
