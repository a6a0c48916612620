"""The ObjectNav (and PointNav) task: episodes, goal sets, set-up and the ground-truth tracker of success and SPL."""
