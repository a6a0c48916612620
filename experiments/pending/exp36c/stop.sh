#!/usr/bin/env bash
# Stop issue 36's chain gracefully (each training child writes its checkpoint first), then save it for a commit.
pkill -KILL -f "chain36c|bash -c run"
for P in $(pgrep -f "ovon.cli.main experiment run"); do
  kill -INT -- -"$(ps -o pgid= -p "$P" | tr -d ' ')" 2>/dev/null
done
while pgrep -f "ovon.cli.main (train|evaluate|experiment)" >/dev/null; do sleep 5; done
cd "$(dirname "$0")/../../.." && .venv/bin/python experiments/pending/exp36c/sync.py save && git status --short | tail -5
