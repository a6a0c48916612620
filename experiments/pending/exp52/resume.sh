#!/usr/bin/env bash
# Resume issue 52's chain on a new machine: install, the pinned worktree, the saved root, then the runners.
set -eu
cd "$(dirname "$0")/../../.."
make install
[ -d /work/runs/wt52 ] || git worktree add --detach /work/runs/wt52 "$(cat experiments/pending/exp52/PINNED)"
.venv/bin/python experiments/pending/exp52/sync.py restore
bash experiments/pending/exp52/chain.sh
