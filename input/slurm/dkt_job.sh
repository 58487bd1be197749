# The part of a dktlbm batch job that run_one.slurm, sweep_array.slurm and the sweep.slurm
# written by `postproc/sweep.py slurm` share (sweep.py copies this file into sweep.slurm, so a
# sweep directory holds all it needs). Sourced by bash; it defines functions only.
#
# dkt_chain runs one dktlbm run as one link of a chain of jobs: skip it when it is finished,
# resume it from its newest checkpoint, start it with the chosen MPI launcher, pass SIGUSR1 on
# to it once it has its signal handlers, and after it has stopped with a checkpoint submit the
# same script again with the resources of this job. The caller sets, before calling it:
#   exe, scene              the executable and the scene file
#   options                 (array) further dktlbm options
#   OUTDIR, name            the output directory (absolute) and the scene's name
#   log                     file the run's output is appended to; empty = this job's output
#   MAX_RESUBMITS, RESUBMIT the chain's limit and count
#   resubmit_extra          (array) sbatch options of its own (the sweep: --array=k)
#   fresh_if_unfinished     1 = start an unfinished run without checkpoint over (a sweep)
# and defines say (a message line) and hint_submit (how to submit again by hand).
#
# Settings read from the environment (handed on to every resubmitted job):
#   DKT_LAUNCHER  srun | mpirun | auto (default): how the ranks are started, see dkt_launcher
#   DKT_SRUN_MPI  srun's --mpi plugin (pmix, pmi2, none); empty = found by dkt_launcher
#   MPIRUN        the mpirun of the MPI dktlbm was built with (default mpirun)

# srun's MPI plugin for `exe`, printed (empty: leave it to srun, i.e. SLURM_MPI_TYPE or the
# site's MpiDefault). Open MPI needs pmix (its builds lack Slurm's PMI-2 client); other MPIs
# (MPICH, Intel MPI) take pmi2, else pmix. Prints "unusable" when Open MPI meets no pmix.
dkt_srun_mpi() {
  local list site openmpi=0
  if [ -n "${DKT_SRUN_MPI:-}" ]; then
    printf '%s\n' "$DKT_SRUN_MPI"
    return
  fi
  [ -n "${SLURM_MPI_TYPE:-}" ] && return
  site=$(scontrol show config 2>/dev/null | sed -n 's/^MpiDefault *= *//p')
  case $site in '' | none) ;; *) return ;; esac
  list=$(srun --mpi=list 2>&1) || list=''
  if ldd "$(command -v "$exe")" 2>/dev/null | grep -q 'libopen-pal\|libopen-rte'; then
    openmpi=1
  fi
  if printf '%s\n' "$list" | grep -qw 'pmi2' && [ "$openmpi" -eq 0 ]; then
    echo pmi2
  elif printf '%s\n' "$list" | grep -qw 'pmix'; then
    echo pmix
  elif [ "$openmpi" -eq 1 ]; then
    echo unusable
  fi
}

# The launch command, into the array `launch`: srun with its MPI plugin, or mpirun (inside a
# Slurm job Open MPI's mpirun takes the job's nodes and tasks from Slurm). DKT_LAUNCHER=auto
# takes srun when it can start this executable, else mpirun.
dkt_launcher() {
  local mode=${DKT_LAUNCHER:-auto} plugin=''
  case $mode in
    srun | mpirun | auto) ;;
    *) say "error: DKT_LAUNCHER=$mode; allowed: srun, mpirun, auto"; return 2 ;;
  esac
  if [ "$mode" != mpirun ]; then plugin=$(dkt_srun_mpi); fi
  if [ "$mode" = auto ]; then
    mode=srun
    if [ "$plugin" = unusable ] || ! command -v srun >/dev/null; then mode=mpirun; fi
  fi
  if [ "$mode" = mpirun ]; then
    launch=("${MPIRUN:-mpirun}" -n "${SLURM_NTASKS:-1}")
    return 0
  fi
  launch=(srun)
  case $plugin in
    '' | unusable) ;;
    *) launch+=("--mpi=$plugin") ;;
  esac
  if [ "$plugin" = unusable ]; then
    say "warning: srun lists no pmix plugin, which Open MPI needs; DKT_LAUNCHER=mpirun may work"
  fi
}

# The newest checkpoint, as recorded in <name>.checkpoint (empty if there is none). If the
# recorded file is gone because the output directory was moved, the checkpoint of the same name
# in OUTDIR.
latest_checkpoint() {
  local path=''
  [ -e "$pointer" ] || return 0
  read -r path < "$pointer"
  if [ -n "$path" ] && [ ! -f "$path" ] && [ -f "$OUTDIR/${path##*/}" ]; then
    path=$OUTDIR/${path##*/}
  fi
  printf '%s\n' "$path"
}

# One field of `scontrol show job` for this job (empty outside a job or when unset).
dkt_job_field() {
  [ -n "${SLURM_JOB_ID:-}" ] || return 0
  printf '%s\n' "$job_record" | tr ' ' '\n' | sed -n "s|^$1=||p" | head -n 1
}

# Slurm runs a copy of the batch script kept in its spool directory (removed when the job
# ends), so $0 is not the file that was submitted. The file to submit: SUBMIT_SCRIPT when set;
# else the Command= field of `scontrol show job` (the script as sbatch was given it) if that
# file is still there; else $0, Slurm's copy, which exists while this job runs (sbatch reads a
# script when it submits it); it only misses edits made to the original since.
script_to_submit() {
  local command
  if [ -n "${SUBMIT_SCRIPT:-}" ]; then
    printf '%s\n' "$SUBMIT_SCRIPT"
    return
  fi
  command=$(dkt_job_field Command)
  case $command in
    /*) ;;
    ?*) command=${SLURM_SUBMIT_DIR:-$PWD}/$command ;;
  esac
  if [ -n "$command" ] && [ -f "$command" ]; then
    printf '%s\n' "$command"
  else
    printf '%s\n' "$0"
  fi
}

# The job's output file as a pattern for the next job: its job ids turned back into %A_%a / %j.
dkt_output_pattern() {
  local path=$1 dir base
  dir=${path%/*}
  base=${path##*/}
  if [ -n "${SLURM_ARRAY_JOB_ID:-}" ] && [ -n "${SLURM_ARRAY_TASK_ID:-}" ]; then
    base=${base//${SLURM_ARRAY_JOB_ID}_${SLURM_ARRAY_TASK_ID}/%A_%a}
  fi
  base=${base//${SLURM_JOB_ID}/%j}
  printf '%s/%s\n' "$dir" "$base"
}

# The job's own messages go to the run's directory: when Slurm writes them to a default
# slurm-*.out file in the submit directory, that file is moved to OUTDIR (the messages Slurm
# itself adds at the end of the job are lost with it) and the next jobs write there directly.
dkt_move_output() {
  local out
  out=$(dkt_job_field StdOut)
  output_pattern=''
  [ -n "$out" ] || return 0
  output_pattern=$(dkt_output_pattern "$out")
  case ${out##*/} in slurm-*) ;; *) return 0 ;; esac
  [ "${out%/*}" = "${SLURM_SUBMIT_DIR:-}" ] && [ "${out%/*}" != "$OUTDIR" ] || return 0
  [ "$(dkt_job_field StdErr)" = "$out" ] || return 0
  exec >> "$OUTDIR/${out##*/}" 2>&1 && rm -f "$out" || return 0
  output_pattern=$OUTDIR/${output_pattern##*/}
}

# sbatch options that give the next job the resources of this one: options given on this
# job's sbatch command line are not in the script, and the next job must not fall back to
# the script's #SBATCH lines (a task count the node cannot hold waits forever).
dkt_inherit() {
  local value
  inherit=()
  [ -n "${SLURM_JOB_ID:-}" ] || return 0
  value=$(dkt_job_field NumTasks)
  [ -n "$value" ] && inherit+=("--ntasks=$value")
  value=$(dkt_job_field NumNodes)
  [ -n "$value" ] && inherit+=("--nodes=$value")
  value=$(dkt_job_field CPUs/Task)
  [ -n "$value" ] && inherit+=("--cpus-per-task=$value")
  value=$(dkt_job_field TimeLimit)
  case $value in '' | UNLIMITED | Partition_Limit) ;; *) inherit+=("--time=$value") ;; esac
  value=$(dkt_job_field Partition)
  [ -n "$value" ] && inherit+=("--partition=$value")
  for field in Account QOS Reservation; do
    value=$(dkt_job_field "$field")
    case $value in '' | '(null)') ;; *) inherit+=("--$(tr 'A-Z' 'a-z' <<< "$field")=$value") ;; esac
  done
  value=$(dkt_job_field JobName)
  [ -n "$value" ] && inherit+=("--job-name=$value")
  if [ -n "$output_pattern" ]; then inherit+=("--output=$output_pattern" --open-mode=append); fi
}

# Run `launch` + dktlbm + args in the background and wait for it. SIGUSR1 to this shell is
# passed on once the run has its handlers (it creates the file DKTLBM_READY_FILE then); one
# that comes earlier is held until then, so that it stops the run rather than kills it (one
# that came before this function, noted as early_usr1=1 by the script's first trap, too).
# Sets status (the run's exit status) and stop_asked (1 after SIGUSR1).
dkt_run() {
  local ready=$OUTDIR/.ready.${SLURM_JOB_ID:-$$} held=0 tick
  stop_asked=0
  pid=''
  forward_usr1() {
    stop_asked=1
    if [ -n "$pid" ] && [ -e "$ready" ]; then
      say "SIGUSR1: the time limit is near; the run is to write a checkpoint and stop"
      kill -USR1 "$pid" 2>/dev/null
    else
      held=1
      say "SIGUSR1: the time limit is near; held until the run has started"
    fi
  }
  trap forward_usr1 USR1
  # Only now look at the first trap's note: read before this trap was set, a signal coming in
  # between would set early_usr1 too late and be lost.
  if [ "${early_usr1:-0}" -eq 1 ] && [ "$held" -eq 0 ]; then
    held=1
    stop_asked=1
    say "SIGUSR1 came before the run started: held until it has"
  fi
  rm -f "$ready"
  if [ -n "$log" ]; then
    DKTLBM_READY_FILE=$ready "${launch[@]}" "$exe" "$@" >> "$log" 2>&1 &
  else
    DKTLBM_READY_FILE=$ready "${launch[@]}" "$exe" "$@" &
  fi
  pid=$!
  # a trap runs only between commands: wait in short steps, each of which it can end
  while kill -0 "$pid" 2>/dev/null; do
    if [ "$held" -eq 1 ] && [ -e "$ready" ]; then
      held=0
      say "the run has started: SIGUSR1 passed on"
      kill -USR1 "$pid" 2>/dev/null
    fi
    sleep 0.2 &
    tick=$!
    wait "$tick" 2>/dev/null
  done
  wait "$pid"
  status=$?
  pid=''
  rm -f "$ready"
}

# How to go on by hand, for the cases where the chain ends.
resume_hint() {
  local by_hand
  by_hand=$(printf '%q ' "${launch[@]}" "$exe" "${args[@]}" --restart "$1")
  hint_submit
  say "or by hand: ${by_hand% }"
}

# One link of the chain (see the top). Returns the job's exit status: 0 = finished, or
# stopped with a checkpoint and the next job submitted; dktlbm's status = it failed; 1 = it
# stopped before its end and no next job was submitted; 2 = a setting is wrong.
dkt_chain() {
  local finished=$OUTDIR/$name.finished restart_from checkpoint script next submit jobid
  pointer=$OUTDIR/$name.checkpoint
  job_record=''
  if [ -n "${SLURM_JOB_ID:-}" ]; then
    job_record=$(scontrol show job "$SLURM_JOB_ID" 2>/dev/null)
  fi
  dkt_move_output
  if [ -n "${SLURM_JOB_ID:-}" ] && ! grep -qx "$SLURM_JOB_ID" "$OUTDIR/jobs" 2>/dev/null; then
    printf '%s\n' "$SLURM_JOB_ID" >> "$OUTDIR/jobs"
  fi
  command -v "$exe" >/dev/null || { say "error: $exe is not an executable"; return 2; }
  if [ -e "$finished" ]; then
    say "$name is finished ($finished exists); nothing to do"
    return 0
  fi
  dkt_launcher || return 2
  args=("$scene" "${options[@]}" --set "output.dir=$OUTDIR")
  restart_from=$(latest_checkpoint)
  if [ -e "$pointer" ]; then
    if [ -z "$restart_from" ] || [ ! -f "$restart_from" ]; then
      say "error: $pointer names checkpoint '$restart_from', which does not exist"
      return 2
    fi
    args+=(--restart "$restart_from")
  elif [ "${fresh_if_unfinished:-0}" -eq 1 ] && [ -e "$OUTDIR/$name.h5" ]; then
    say "$OUTDIR/$name.h5 is unfinished and has no checkpoint: the run starts over"
    args+=(--set output.overwrite=.true.)
  fi

  say "job ${SLURM_JOB_ID:-none} (resubmission $RESUBMIT of at most $MAX_RESUBMITS):" \
    "${launch[*]} $exe ${args[*]}"
  if [ -n "$log" ]; then
    printf '# job %s: %s\n' "${SLURM_JOB_ID:-none}" "$(printf '%q ' "${launch[@]}" "$exe" "${args[@]}")" >> "$log"
  fi
  dkt_run "${args[@]}"

  if [ "$status" -ne 0 ] && [ "$stop_asked" -eq 0 ]; then
    say "dktlbm failed (exit status $status${log:+, see $log}); not resubmitted"
    return "$status"
  fi
  if [ -e "$finished" ]; then
    say "the run is finished ($finished)"
    return 0
  fi
  if [ "$status" -ne 0 ]; then
    say "dktlbm ended with status $status after SIGUSR1; going on from its newest checkpoint"
  fi
  checkpoint=$(latest_checkpoint)
  if [ -z "$checkpoint" ] || [ ! -f "$checkpoint" ]; then
    say "the run stopped before its end without a checkpoint to resume from; not resubmitted"
    return 1
  fi
  if [ "$checkpoint" = "$restart_from" ]; then
    # the run stopped again without progress: resubmitting would only repeat that
    say "no checkpoint newer than $checkpoint, the one this job resumed from; not resubmitted"
    resume_hint "$checkpoint"
    return 1
  fi
  say "the run stopped with the checkpoint $checkpoint"
  if [ "$RESUBMIT" -ge "$MAX_RESUBMITS" ]; then
    say "not resubmitted: this job was resubmission $RESUBMIT, MAX_RESUBMITS is $MAX_RESUBMITS"
    resume_hint "$checkpoint"
    return 1
  fi

  # --export=ALL hands this job's environment (the settings included) to the next job, with
  # the count of resubmissions; afterany makes it wait until this job has ended, so that the
  # two never overlap; dkt_inherit gives it this job's resources.
  script=$(script_to_submit)
  next=$((RESUBMIT + 1))
  dkt_inherit
  submit=(sbatch --parsable "${inherit[@]}" "${resubmit_extra[@]}" "--export=ALL,RESUBMIT=$next")
  if [ -n "${SLURM_JOB_ID:-}" ]; then submit+=("--dependency=afterany:$SLURM_JOB_ID"); fi
  submit+=("$script")
  say "resubmitting (resubmission $next of at most $MAX_RESUBMITS): ${submit[*]}"
  if ! jobid=$("${submit[@]}"); then
    say "error: sbatch failed; the run was not resubmitted"
    resume_hint "$checkpoint"
    return 1
  fi
  jobid=${jobid%%;*}
  jobid=${jobid##* }
  # every job of the chain, for `scancel` (the names stay the same, the ids do not)
  printf '%s\n' "$jobid" >> "$OUTDIR/jobs"
  say "submitted job $jobid"
  return 0
}

# Array task SLURM_ARRAY_TASK_ID of the sweep whose plan is $1 (runs.csv of `sweep.py plan`):
# row k of the plan, read as sweep.py reads it (Python's csv module, by column name; the
# command split as shlex does), run in DIR/<id> with its output appended to DIR/<id>/run.log,
# as one link of a chain (dkt_chain) that resubmits this array index only.
dkt_sweep_task() {
  local runs=$1 task row id plan_args sweep
  log=''
  say() {
    local line
    line="$(date '+%F %T') sweep[${SLURM_ARRAY_TASK_ID:-?}]: $*"
    printf '%s\n' "$line"
    if [ -n "$log" ]; then printf '%s\n' "$line" >> "$log"; fi
  }
  task=${SLURM_ARRAY_TASK_ID:-}
  case $task in
    '' | *[!0-9]*) say "error: submit this script as a job array (sbatch --array=...)"; return 2 ;;
  esac
  case "$MAX_RESUBMITS,$RESUBMIT" in
    *[!0-9,]* | ,* | *,) say "error: MAX_RESUBMITS and RESUBMIT must be whole numbers"; return 2 ;;
  esac
  [ -f "$runs" ] || { say "error: plan $runs not found (in $PWD)"; return 2; }
  # Python prints id and the command as bash assignments (quoted by shlex.quote) for eval.
  row=$(python3 - "$runs" "$task" <<'PY'
import csv
import shlex
import sys

path, k = sys.argv[1], int(sys.argv[2])
with open(path, newline="") as f:
    reader = csv.DictReader(f)
    missing = {"id", "command"} - set(reader.fieldnames or [])
    if missing:
        sys.exit(f"{path}: not a sweep plan (no column {', '.join(sorted(missing))})")
    rows = list(reader)
if not 0 <= k < len(rows):
    sys.exit(f"{path}: no row {k}; the plan has {len(rows)} runs (array indices 0-{len(rows) - 1})")
args = shlex.split(rows[k]["command"])
if len(args) < 2 or not rows[k]["id"]:
    sys.exit(f"{path}: row {k} has no id or no executable and scene file")
print("id=" + shlex.quote(rows[k]["id"]))
print("plan_args=(" + " ".join(shlex.quote(a) for a in args) + ")")
PY
  ) || { say "error: cannot read row $task of $runs"; return 2; }
  id='' plan_args=()
  eval "$row"
  exe=${DKTLBM:-${plan_args[0]}}
  scene=${plan_args[1]}
  options=("${plan_args[@]:2}")
  # dktlbm names its files after the scene file: its basename without the extension (a
  # leading dot does not start an extension), as Path(scene).stem in sweep.py.
  name=${scene##*/}
  case $name in ?*.*) name=${name%.*} ;; esac
  sweep=$(cd "$(dirname "$runs")" && pwd)
  OUTDIR=$sweep/$id
  mkdir -p "$OUTDIR" || { say "error: cannot create the run directory $OUTDIR"; return 2; }
  log=$OUTDIR/run.log
  resubmit_extra=("--array=$task")
  fresh_if_unfinished=1
  hint_submit() {
    say "to go on: RUNS=$runs sbatch --array=$task $(script_to_submit) (from $PWD)"
  }
  say "run $id"
  dkt_chain
}
