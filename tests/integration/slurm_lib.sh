# shellcheck shell=bash
# A real one-node Slurm cluster on loopback, for the tests and benchmarks that submit
# deploy/batch/slurm/ (sourced, not run). Debian's slurm-wlm and munge (scripts/setup.sh) run it
# without systemd in a few seconds: munged with a key of its own, slurmctld and slurmd as root
# (SlurmUser=root, the only user a test can rely on), every file under one folder and on ports
# nobody uses, so that two runs on one machine do not meet. The caller defines free_port (lib.sh).
#
#   slurm_start DIR MAX_ARRAY_SIZE CPUS   starts the cluster; exports SLURM_CONF (every Slurm
#                                         command then talks to it)
#   slurm_stop                            stops every daemon slurm_start started (call from an
#                                         EXIT trap: it is safe to call twice, or before a start)
#   slurm_wait_jobs SECONDS JOBID...      waits until every task of the jobs has ended
#   slurm_job_states JOBID                one "ARRAY_TASK STATE" line per task of JOBID
#
# The node says CPUs=CPUS and 4 GiB of memory whatever the machine has (config_overrides: a node
# smaller than its configuration is not drained), so build.sbatch's --cpus-per-task=2 and --mem=2G
# fit on any machine; memory is not a consumable resource here (CR_Core), so nothing is reserved.

SLURM_DIR=""

# slurm_poll SECONDS WHAT CMD...: runs CMD every 0.1 s until it succeeds; fails naming WHAT after
# SECONDS.
slurm_poll() {
  local secs=$1 what=$2
  local deadline=$((SECONDS + secs))
  shift 2
  until "$@"; do
    ((SECONDS < deadline)) || { slurm_logs; fail "Slurm: not $what within ${secs}s"; }
    sleep 0.1
  done
}

# tail_logs FILE...: the last 20 lines of each non-empty FILE, on stderr.
tail_logs() {
  local f
  for f in "$@"; do
    [[ -s $f ]] || continue
    echo "---- $f (last 20 lines):" >&2
    tail -n 20 "$f" >&2
  done
}

# slurm_logs: the daemons' logs.
slurm_logs() {
  [[ -n $SLURM_DIR ]] || return 0
  tail_logs "$SLURM_DIR"/log/*.log
}

slurm_node_idle() { [[ $(sinfo -h -o %T 2>/dev/null) == idle ]]; }
slurm_munge_up() { [[ -S $SLURM_DIR/munge/munge.socket ]] && munge -n -S "$SLURM_DIR/munge/munge.socket" >/dev/null 2>&1; }

slurm_start() {
  local d=$1 max_array=$2 cpus=$3
  local f
  for f in munged slurmctld slurmd sinfo sbatch scontrol; do
    command -v "$f" >/dev/null 2>&1 || fail "missing '$f' (Debian packages slurm-wlm and munge: run scripts/setup.sh)"
  done
  ((EUID == 0)) || fail "the Slurm cluster runs its daemons as root (SlurmUser=root): run as root"
  SLURM_DIR=$d
  mkdir -p "$d"/{state,spool,munge,log}
  chmod 700 "$d/munge"
  head -c 1024 /dev/urandom >"$d/munge/munge.key"
  chmod 400 "$d/munge/munge.key"
  munged --force --socket="$d/munge/munge.socket" --key-file="$d/munge/munge.key" \
    --log-file="$d/log/munged.log" --pid-file="$d/munge/munged.pid" --seed-file="$d/munge/munged.seed" ||
    fail "munged did not start (see $d/log/munged.log)"
  slurm_poll 20 "munged answers" slurm_munge_up
  local ctld_port slurmd_port
  ctld_port=$(free_port)
  slurmd_port=$(free_port)
  while [[ $slurmd_port == "$ctld_port" ]]; do slurmd_port=$(free_port); done
  cat >"$d/slurm.conf" <<EOF
ClusterName=vtstest
SlurmctldHost=localhost(127.0.0.1)
SlurmctldPort=$ctld_port
SlurmdPort=$slurmd_port
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
AuthInfo=socket=$d/munge/munge.socket
CredType=cred/munge
StateSaveLocation=$d/state
SlurmdSpoolDir=$d/spool
SlurmctldPidFile=$d/slurmctld.pid
SlurmdPidFile=$d/slurmd.pid
SlurmctldLogFile=$d/log/slurmctld.log
SlurmdLogFile=$d/log/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SwitchType=switch/none
MpiDefault=none
ReturnToService=2
SchedulerType=sched/backfill
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
SlurmdParameters=config_overrides
MaxArraySize=$max_array
MinJobAge=3600
JobCompType=jobcomp/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
PlugStackConfig=/dev/null
NodeName=vtsnode NodeAddr=127.0.0.1 CPUs=$cpus RealMemory=4096 State=UNKNOWN
PartitionName=test Nodes=ALL Default=YES MaxTime=INFINITE State=UP
EOF
  export SLURM_CONF=$d/slurm.conf
  # -i: ignore any saved state (there is none: a fresh StateSaveLocation).
  slurmctld -i || { slurm_logs; fail "slurmctld did not start"; }
  slurmd -N vtsnode || { slurm_logs; fail "slurmd did not start"; }
  slurm_poll 60 "the node is idle (sinfo)" slurm_node_idle
}

# slurm_stop_one PIDFILE: SIGTERM, then SIGKILL after 10 s; returns once the process is gone.
slurm_stop_one() {
  local pid i
  [[ -s $1 ]] || return 0
  pid=$(<"$1")
  [[ $pid =~ ^[0-9]+$ ]] || return 0
  kill -TERM "$pid" 2>/dev/null || return 0
  for ((i = 0; i < 100; i++)); do
    kill -0 "$pid" 2>/dev/null || return 0
    sleep 0.1
  done
  kill -KILL "$pid" 2>/dev/null || true
  for ((i = 0; i < 50; i++)); do
    kill -0 "$pid" 2>/dev/null || return 0
    sleep 0.1
  done
  echo "Slurm: process $pid ($1) did not end" >&2
}

slurm_stop() {
  [[ -n $SLURM_DIR ]] || return 0
  # slurmd first: it ends the jobs' steps it still runs.
  slurm_stop_one "$SLURM_DIR/slurmd.pid"
  slurm_stop_one "$SLURM_DIR/slurmctld.pid"
  slurm_stop_one "$SLURM_DIR/munge/munged.pid"
}

slurm_job_states() {
  scontrol -o show job "$1" | awk '{
    t = "-"; s = "?"
    for (i = 1; i <= NF; i++) {
      if ($i ~ /^ArrayTaskId=/) t = substr($i, 13)
      if ($i ~ /^JobState=/) s = substr($i, 10)
    }
    print t, s
  }'
}

# True when every task of every job given has ended (a state other than PENDING, RUNNING,
# CONFIGURING, COMPLETING, REQUEUED, SUSPENDED...).
slurm_jobs_ended() {
  local j states
  for j in "$@"; do
    states=$(scontrol -o show job "$j" 2>/dev/null | grep -o 'JobState=[A-Z_]*') || return 1
    grep -qvE 'JobState=(COMPLETED|FAILED|CANCELLED|TIMEOUT|OUT_OF_MEMORY|NODE_FAIL|BOOT_FAIL|DEADLINE|PREEMPTED)$' \
      <<<"$states" && return 1
  done
  return 0
}

slurm_wait_jobs() {
  local secs=$1
  shift
  slurm_poll "$secs" "jobs $* ended" slurm_jobs_ended "$@"
}
