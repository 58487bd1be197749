#!/usr/bin/env bash
# A single-node Slurm on this machine, for tests/test_slurm_real.py (ctest label slurm_real).
#
#   bash tools/slurm-local.sh start    # install if missing, configure, start, wait until idle
#   bash tools/slurm-local.sh stop     # stop the daemons started by `start`, remove the state
#   bash tools/slurm-local.sh status   # exit 0 when the cluster answers
#
# As root on Debian 12 (packages slurmctld slurmd slurm-client munge, Slurm 22.05), without
# systemd: munged, slurmctld and slurmd are started directly and their PIDs recorded. All
# state lives in DKT_SLURM_DIR (default /tmp/dkt-slurm-local); the configuration is written
# there and linked from /etc/slurm/slurm.conf, which must not hold another configuration.
# The node gets this machine's CPUs and memory; MpiDefault=none, as on many sites, so that a
# job has to choose its MPI plugin itself. Start it under `nice` and the jobs run niced too.
# Both commands are idempotent.
set -euo pipefail

dir=${DKT_SLURM_DIR:-/tmp/dkt-slurm-local}
conf=/etc/slurm/slurm.conf
marker="# written by tools/slurm-local.sh"

die() {
  echo "slurm-local: error: $*" >&2
  exit 1
}
say() { echo "slurm-local: $*"; }

running() { [[ -f "$dir/$1.pid" ]] && kill -0 "$(cat "$dir/$1.pid")" 2>/dev/null; }

install_packages() {
  local missing=()
  command -v slurmctld >/dev/null || missing+=(slurmctld)
  command -v slurmd >/dev/null || missing+=(slurmd)
  command -v sbatch >/dev/null || missing+=(slurm-client)
  command -v munged >/dev/null || missing+=(munge)
  [[ ${#missing[@]} -eq 0 ]] && return 0
  command -v apt-get >/dev/null || die "missing ${missing[*]} and no apt-get (Debian 12 expected)"
  say "installing ${missing[*]}"
  # the packages' own service starts are kept off while installing: this script starts the
  # daemons itself, with its own configuration
  local policy=/usr/sbin/policy-rc.d added=0
  if [[ ! -e $policy ]]; then
    printf '#!/bin/sh\nexit 101\n' > "$policy" && chmod 755 "$policy" && added=1
  fi
  local ok=0
  DEBIAN_FRONTEND=noninteractive apt-get install -y -q "${missing[@]}" > "$dir/apt.log" 2>&1 ||
    { DEBIAN_FRONTEND=noninteractive apt-get update -q >> "$dir/apt.log" 2>&1 &&
      DEBIAN_FRONTEND=noninteractive apt-get install -y -q "${missing[@]}" >> "$dir/apt.log" 2>&1; } ||
    ok=1
  [[ $added -eq 1 ]] && rm -f "$policy"
  [[ $ok -eq 0 ]] || { tail -n 20 "$dir/apt.log" >&2; die "apt-get install ${missing[*]} failed (log: $dir/apt.log)"; }
}

write_config() {
  local host cpus mem
  host=$(hostname -s)
  cpus=$(nproc)
  mem=$(awk '/^MemTotal:/ {print int($2 / 1024 * 0.9)}' /proc/meminfo)
  mkdir -p "$dir/ctld" "$dir/d" /etc/slurm
  cat > "$dir/slurm.conf" <<EOF
$marker; removed by its stop
ClusterName=dktlocal
SlurmctldHost=$host
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
CredType=cred/munge
AuthInfo=socket=$dir/munge.socket
MpiDefault=none
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
ReturnToService=2
SlurmctldTimeout=10
SlurmdTimeout=30
InactiveLimit=0
KillWait=10
MinJobAge=300
StateSaveLocation=$dir/ctld
SlurmdSpoolDir=$dir/d
SlurmctldPidFile=$dir/slurmctld.pid.slurm
SlurmdPidFile=$dir/slurmd.pid.slurm
SlurmctldLogFile=$dir/slurmctld.log
SlurmdLogFile=$dir/slurmd.log
NodeName=$host CPUs=$cpus RealMemory=$mem State=UNKNOWN
PartitionName=debug Nodes=$host Default=YES MaxTime=INFINITE State=UP OverSubscribe=NO
EOF
  if [[ -e $conf || -L $conf ]] && ! grep -q "^$marker" "$conf" 2>/dev/null; then
    die "$conf exists and was not written by this script: a Slurm is configured already"
  fi
  ln -sfn "$dir/slurm.conf" "$conf"
}

start() {
  [[ $(id -u) -eq 0 ]] || die "start needs root (it installs packages and runs the daemons)"
  mkdir -p "$dir" && chmod 700 "$dir"
  install_packages
  if running slurmctld && running slurmd && running munged; then
    say "already running (state in $dir)"
  else
    write_config
    if ! running munged; then
      [[ -f $dir/munge.key ]] || { dd if=/dev/urandom of="$dir/munge.key" bs=1024 count=1 2>/dev/null &&
        chmod 400 "$dir/munge.key"; }
      munged --force --key-file="$dir/munge.key" --socket="$dir/munge.socket" \
        --pid-file="$dir/munged.pid.munge" --log-file="$dir/munged.log" \
        --seed-file="$dir/munge.seed" || die "munged did not start (log: $dir/munged.log)"
      cp "$dir/munged.pid.munge" "$dir/munged.pid"
    fi
    if ! running slurmctld; then
      slurmctld -i -f "$conf" || die "slurmctld did not start (log: $dir/slurmctld.log)"
      sleep 1
      cp "$dir/slurmctld.pid.slurm" "$dir/slurmctld.pid" 2>/dev/null ||
        die "slurmctld did not start (log: $dir/slurmctld.log)"
    fi
    if ! running slurmd; then
      slurmd -f "$conf" || die "slurmd did not start (log: $dir/slurmd.log)"
      sleep 1
      cp "$dir/slurmd.pid.slurm" "$dir/slurmd.pid" 2>/dev/null ||
        die "slurmd did not start (log: $dir/slurmd.log)"
    fi
  fi
  local t
  for t in $(seq 60); do
    if sinfo -h -o '%T' 2>/dev/null | grep -qx 'idle'; then
      say "up: $(sinfo -h -o '%N %c CPUs %m MB %T' | head -n 1) (state in $dir)"
      return 0
    fi
    sleep 1
  done
  sinfo >&2 || true
  die "the node did not become idle within 60 s (logs in $dir)"
}

stop() {
  local name pid
  if command -v scancel >/dev/null && [[ -f $dir/slurmctld.pid ]]; then
    scancel --full --user=root 2>/dev/null || true
  fi
  for name in slurmd slurmctld munged; do
    if running "$name"; then
      pid=$(cat "$dir/$name.pid")
      kill "$pid"
      for _ in $(seq 20); do kill -0 "$pid" 2>/dev/null || break; sleep 0.5; done
      kill -0 "$pid" 2>/dev/null && kill -KILL "$pid"
    fi
  done
  if [[ -L $conf ]] && grep -q "^$marker" "$conf" 2>/dev/null; then rm -f "$conf"; fi
  rm -rf "$dir"
  say "stopped"
}

case ${1:-} in
  start) start ;;
  stop) stop ;;
  status) sinfo -h -o '%N %T' ;;
  *) echo "usage: $0 start|stop|status" >&2; exit 2 ;;
esac
