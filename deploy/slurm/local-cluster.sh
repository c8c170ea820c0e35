#!/usr/bin/env bash
# A single-node Slurm cluster on this machine, for the experiment runner's
# Slurm tests: `local-cluster.sh start DIR` writes DIR/slurm.conf, starts
# munged, slurmctld and slurmd (as root), and waits until the node is idle;
# `local-cluster.sh stop DIR` stops exactly the daemons it started. Clients
# use it with SLURM_CONF=DIR/slurm.conf. Needs Debian's slurm-wlm and munge.
set -euo pipefail

cmd=${1:?usage: local-cluster.sh start|stop DIR}
dir=$(realpath -m "${2:?usage: local-cluster.sh start|stop DIR}")

case "$cmd" in
start)
  for tool in munged mungekey slurmctld slurmd sinfo; do
    command -v "$tool" >/dev/null || { echo "missing $tool: apt-get install slurm-wlm munge" >&2; exit 2; }
  done
  mkdir -p "$dir"/{state,spool,log,munge}
  chown munge: "$dir/munge"
  chmod 700 "$dir/munge"
  # munged refuses group/world-writable parents; keep its files under $dir/munge.
  [ -f "$dir/munge/munge.key" ] || mungekey -c -k "$dir/munge/munge.key"
  chown munge: "$dir/munge/munge.key"
  runuser -u munge -- munged --key-file "$dir/munge/munge.key" \
    --socket "$dir/munge/munge.socket" --pid-file "$dir/munge/munged.pid" \
    --log-file "$dir/munge/munged.log" --seed-file "$dir/munge/munged.seed" --force
  # Two free ports, so that clusters of concurrent test runs do not meet.
  in_use() { (exec 3<>"/dev/tcp/127.0.0.1/$1") 2>/dev/null; }
  while :; do
    ctld_port=$(( 20000 + RANDOM % 20000 )); slurmd_port=$(( ctld_port + 1 ))
    in_use "$ctld_port" || in_use "$slurmd_port" || break
  done
  cpus=$(nproc)
  memory=$(( $(awk '/MemTotal/ {print $2}' /proc/meminfo) / 1024 - 1024 ))
  host=$(hostname -s)
  cat > "$dir/slurm.conf" <<CONF
ClusterName=nuno-local
SlurmctldHost=$host
AuthType=auth/munge
AuthInfo=socket=$dir/munge/munge.socket
CredType=cred/munge
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SlurmUser=root
SlurmdUser=root
StateSaveLocation=$dir/state
SlurmdSpoolDir=$dir/spool
SlurmctldPidFile=$dir/slurmctld.pid
SlurmdPidFile=$dir/slurmd.pid
SlurmctldLogFile=$dir/log/slurmctld.log
SlurmdLogFile=$dir/log/slurmd.log
SlurmctldPort=$ctld_port
SlurmdPort=$slurmd_port
ReturnToService=2
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
MpiDefault=none
JobAcctGatherType=jobacct_gather/none
NodeName=$host CPUs=$cpus RealMemory=$memory State=UNKNOWN
PartitionName=local Nodes=$host Default=YES MaxTime=INFINITE State=UP
CONF
  SLURM_CONF="$dir/slurm.conf" slurmctld -f "$dir/slurm.conf"
  SLURM_CONF="$dir/slurm.conf" slurmd -f "$dir/slurm.conf"
  for _ in $(seq 60); do
    state=$(SLURM_CONF="$dir/slurm.conf" sinfo -h -o %t 2>/dev/null || true)
    case "$state" in idle*|mix*|alloc*) echo "slurm up: $dir/slurm.conf"; exit 0 ;; esac
    sleep 0.5
  done
  echo "slurm did not come up; logs in $dir/log" >&2
  exit 1
  ;;
stop)
  pids=""
  for pidfile in "$dir/slurmd.pid" "$dir/slurmctld.pid" "$dir/munge/munged.pid"; do
    [ -f "$pidfile" ] || continue
    pid=$(cat "$pidfile")
    kill "$pid" 2>/dev/null && pids="$pids $pid"
  done
  # Wait until they are gone (slurmctld takes a moment to save its state).
  for _ in $(seq 100); do
    alive=""
    for pid in $pids; do kill -0 "$pid" 2>/dev/null && alive=1; done
    [ -z "$alive" ] && exit 0
    sleep 0.1
  done
  echo "slurm daemons still running after 10 s:$pids" >&2
  exit 1
  ;;
*)
  echo "usage: local-cluster.sh start|stop DIR" >&2
  exit 2
  ;;
esac
