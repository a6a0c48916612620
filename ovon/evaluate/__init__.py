"""Evaluation: what runs (`config`), the episodes of a run and its folder (`harness`), the workers that
run them (`worker`, `runner`) and the records they leave (`results`)."""
