#!/usr/bin/env bash
# Start issue 36's chain: two runners on one root at the pinned commit (the second takes the cells the first
# is not running). Needs the worktree and a restored root (see sync.py). Logs: /work/runs/chain36c{,2}.log.
set -u
WT=/work/runs/wt36c
PY="$(cd "$(dirname "$0")/../../.." && pwd)/.venv/bin/python"
run() {  # $1: extra flags, $2: experiments
  cd "$WT" || exit 1
  export OMP_NUM_THREADS=1
  for name in $2; do
    echo "=== $(date -u +%FT%TZ) $name"
    "$PY" -m ovon.cli.main experiment run "$name" --scale cpu --root /work/runs/exp36c $1 || echo "=== $name rc=$?"
  done
  echo "chain done $(date -u +%FT%TZ)"
}
mkdir -p /work/runs
export -f run; export PY WT
nohup setsid nice -n 19 bash -c 'run "" "main trajectories memory noise failures"' >> /work/runs/chain36c.log 2>&1 &
sleep 30
nohup setsid nice -n 19 bash -c 'run "--no-wait --no-report" "main trajectories memory noise"' >> /work/runs/chain36c2.log 2>&1 &
