#!/usr/bin/env bash
# Stop issue 36's chain gracefully, then save it for a commit. Only the runners (`experiment run`) get TERM:
# each passes one TERM to its training or evaluation child and waits (up to 120 s) while a training finishes
# its update and writes a checkpoint, or an evaluation keeps its episodes.jsonl. An extra INT to the child
# would be a "second Ctrl-C": it stops the update at once and loses it (s48 lost dagger-lstm's stop
# checkpoint that way, mid-write).
pkill -KILL -f "chain36c|bash -c run"
pkill -TERM -f "ovon.cli.main experiment run"
while pgrep -f "ovon.cli.main (train|evaluate|experiment)" >/dev/null; do sleep 5; done
cd "$(dirname "$0")/../../.." && .venv/bin/python experiments/pending/exp36c/sync.py save && git status --short | tail -5
