# Sourced by the CI scripts: run_parallel JOBS FUNCTION ARG... calls FUNCTION ARG in the
# background for each ARG, at most JOBS at a time, and returns when all have finished. The
# function records its own result (the callers write a status file per call).
run_parallel() {
  local jobs=$1 fn=$2 running=0
  shift 2
  for arg in "$@"; do
    if [ "$running" -ge "$jobs" ]; then wait -n || true; running=$((running - 1)); fi
    "$fn" "$arg" &
    running=$((running + 1))
  done
  wait
}
