#!/usr/bin/env bash
# Start issue 52's chain: two runners on one root at the pinned commit (the second takes the cells the first
# is not running). Needs the worktree and a restored root (resume.sh). Logs: /work/runs/chain52{,b}.log.
set -u
WT=/work/runs/wt52
PY="$(cd "$(dirname "$0")/../../.." && pwd)/.venv/bin/python"
run() {  # $1: extra flags, $2: experiments
  cd "$WT" || exit 1
  export OMP_NUM_THREADS=1
  for name in $2; do
    echo "=== $(date -u +%FT%TZ) $name"
    "$PY" -m ovon.cli.main experiment run "$name" --scale cpu --root /work/runs/exp52 $1 || echo "=== $name rc=$?"
  done
  echo "chain done $(date -u +%FT%TZ)"
}
mkdir -p /work/runs
export -f run; export PY WT
nohup setsid nice -n 19 bash -c 'run "" "main trajectories memory noise failures"' >> /work/runs/chain52.log 2>&1 &
sleep 30
nohup setsid nice -n 19 bash -c 'run "--no-wait --no-report" "main trajectories memory noise"' >> /work/runs/chain52b.log 2>&1 &
