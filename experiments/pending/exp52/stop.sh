#!/usr/bin/env bash
# Stop issue 52's chain gracefully, then save it for a commit. Only the runners (`experiment run`) get TERM:
# each passes one TERM to its training or evaluation child and waits while a training finishes its update
# and writes a checkpoint, or an evaluation keeps its episodes.jsonl. A second signal to the child would
# stop the update at once and lose it.
pkill -KILL -f "bash -c run"
pkill -TERM -f "ovon.cli.main experiment run"
while pgrep -f "ovon.cli.main (train|evaluate|experiment)" >/dev/null; do sleep 5; done
cd "$(dirname "$0")/../../.." && .venv/bin/python experiments/pending/exp52/sync.py save && git status --short | tail -5
