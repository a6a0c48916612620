"""Pretraining and measuring ovon's own perception (`ovon perception pretrain | evaluate`): labelled frames of
the pretrain houses (frames.py), the world-vl training run (pretrain.py), calibration (calibrate.py) and the
frame-level evaluation on held-out houses beside the oracle (evaluate.py). The network and its three roles live
in `ovon.models.world`."""
