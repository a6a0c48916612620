#!/usr/bin/env bash
# Stop issue 36's chain gracefully, then save it for a commit. Order matters: a runner (`experiment run`) that
# sees its child interrupted goes on to its next cell, so the runners get TERM first; then each training or
# evaluation child gets INT (a training writes its checkpoint; an evaluation keeps its episodes.jsonl).
pkill -KILL -f "chain36c|bash -c run"
pkill -TERM -f "ovon.cli.main experiment run"
sleep 3
pkill -INT -f "ovon.cli.main (train|evaluate)"
while pgrep -f "ovon.cli.main (train|evaluate|experiment)" >/dev/null; do sleep 5; done
cd "$(dirname "$0")/../../.." && .venv/bin/python experiments/pending/exp36c/sync.py save && git status --short | tail -5
