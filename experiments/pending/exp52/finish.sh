#!/usr/bin/env bash
# Issue 52's finish, once the chain printed "chain done": the reports of the re-run replace the committed
# learned-perception reports (the -oracle ones stay), every row's weights are released beside them, and the
# README's table is regenerated. Then by hand: experiments/README.md and docs/results pages, the findings'
# "differs" sentences where a verdict changed, docs/concepts/learned-policies.md; remove experiments/pending/exp52.
set -eu
cd "$(git rev-parse --show-toplevel)"
PY=.venv/bin/python
RUN=/work/runs/exp52
R=experiments/results
for n in main trajectories memory noise failures; do
  $PY -m ovon.cli.main experiment report $n --root $RUN --scale cpu --out "$R/$n"
done
T=$RUN/cpu/train
for c in bc dagger rl bcrl dagrl dagger-seed1 dagrl-seed1; do cp "$T/$c/policy.pt" "$R/main/$c.pt"; done
for c in bc-lstm dagger-lstm rl-lstm bcrl-lstm dagrl-lstm; do cp "$T/$c/policy.pt" "$R/memory/$c.pt"; done
for c in bc-sp dagger-sp bcrl-sp dagrl-sp; do cp "$T/$c/policy.pt" "$R/trajectories/$c.pt"; done
$PY -m ovon.cli.main experiment headline --write README.md
