# shellcheck shell=bash
# Background jobs for setup.sh and test.sh (sourced by them, not run on its own).
#
# Steps that mostly wait (a download, a build beside other steps) run in the background, each with
# its output in a log of its own that is shown when the job is joined, so that parallel steps do
# not interleave their output. A job the script has not joined when it exits (a step failed, or
# Ctrl-C) is stopped rather than left running into the venv or the build tree.
#
#   job_start cargo cargo build --release     # starts it; its output goes to a temporary log
#   ...                                        # other steps
#   job_join cargo "cargo build --release"    # waits, shows the log; exits 1 if the job failed
#   job_collect cargo "cargo build --release" # the same, but returns the job's status instead

_JOBS=()

# job_start NAME CMD...: runs CMD in the background, its output into a temporary log.
job_start() {
  local name=$1
  shift
  local log
  log="$(mktemp "/tmp/sorting_line_${name}.XXXXXX.log")"
  # A process group of its own (setsid), so that stopping the job stops what it started too
  # (setup.sh's pip, cargo's rustc processes).
  local group=()
  command -v setsid >/dev/null 2>&1 && group=(setsid --wait)
  "${group[@]}" "$@" >"$log" 2>&1 &
  printf -v "_JOB_PID_$name" %s "$!"
  printf -v "_JOB_LOG_$name" %s "$log"
  _JOBS+=("$name")
}

# job_collect NAME WHAT: waits for job NAME, prints its log and returns its exit status. If it
# failed, the log goes to stderr followed by "WHAT failed", and the script goes on.
job_collect() {
  local pid_var="_JOB_PID_$1" log_var="_JOB_LOG_$1" status=0
  wait "${!pid_var}" || status=$?
  printf -v "$pid_var" %s ""
  if [[ $status != 0 ]]; then
    cat "${!log_var}" >&2
    echo "$2 failed (exit $status; its output is above)" >&2
  else
    cat "${!log_var}"
  fi
  rm -f "${!log_var}"
  return "$status"
}

# job_join NAME WHAT: job_collect, and if the job failed the script exits 1.
job_join() {
  job_collect "$@" || exit 1
}

_jobs_stop() {
  local name pid_var log_var
  for name in "${_JOBS[@]}"; do
    pid_var="_JOB_PID_$name"
    log_var="_JOB_LOG_$name"
    if [[ -n "${!pid_var}" ]]; then
      kill -- "-${!pid_var}" 2>/dev/null || true
    fi
    rm -f "${!log_var}"
  done
}
trap _jobs_stop EXIT
