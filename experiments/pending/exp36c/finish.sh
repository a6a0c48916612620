#!/usr/bin/env bash
# Issue 36's finish, once the chain printed "chain done": keep the oracle reports as <name>-oracle, write the
# learned-perception reports and release every row's weights beside them (the oracle-era weights move with their reports), then regenerate the README's table.
# Then by hand: mkdocs.yml nav for the -oracle reports, experiments/README.md and docs/results/index.md
# paragraphs, docs/concepts/learned-policies.md, remove experiments/pending/.
set -eu
cd "$(git rev-parse --show-toplevel)"
PY=.venv/bin/python
RUN=/work/runs/exp36c
R=experiments/results
for n in main trajectories memory noise failures; do
  [ -d "$R/$n-oracle" ] || git mv "$R/$n" "$R/$n-oracle"
done
for n in main trajectories memory noise failures; do
  $PY -m ovon.cli.main experiment report $n --root $RUN --scale cpu --out "$R/$n"
done
T=$RUN/cpu/train
for c in bc dagger rl bcrl dagrl dagger-seed1 dagrl-seed1; do cp "$T/$c/policy.pt" "$R/main/$c.pt"; done
for c in bc-lstm dagger-lstm rl-lstm bcrl-lstm dagrl-lstm; do cp "$T/$c/policy.pt" "$R/memory/$c.pt"; done
for c in bc-sp dagger-sp bcrl-sp dagrl-sp; do cp "$T/$c/policy.pt" "$R/trajectories/$c.pt"; done
$PY -m ovon.cli.main experiment headline --write README.md
