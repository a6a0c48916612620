"""The training loop's stop request (ovon/train/stop.py): the first Ctrl-C / SIGTERM is a request, a
second Ctrl-C stops now, later SIGTERMs are ignored, and the handlers go back when the loop ends."""

from __future__ import annotations

import os
import signal
import time

import pytest

from ovon.train.stop import StopRequest


def _deliver(sig: int) -> None:
    os.kill(os.getpid(), sig)
    time.sleep(0.05)  # Python runs the handler at the next bytecode boundary of the main thread


@pytest.fixture
def saved_handlers():
    saved = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    yield
    for s, h in saved.items():
        signal.signal(s, h)


def test_first_signal_requests_a_stop_second_ctrl_c_stops_now(saved_handlers, capsys):
    # Python's own Ctrl-C handler to start from (a shell's background job, e.g. under nohup, starts ignoring it)
    signal.signal(signal.SIGINT, signal.default_int_handler)
    stop = StopRequest()
    stop.arm()
    _deliver(signal.SIGTERM)
    assert stop.requested
    assert "stopping after this update, with a checkpoint" in capsys.readouterr().err
    _deliver(signal.SIGTERM)  # a process group's stop, then the runner's own: ignored
    with pytest.raises(KeyboardInterrupt):
        _deliver(signal.SIGINT)
    stop.disarm()
    assert signal.getsignal(signal.SIGTERM) == signal.SIG_IGN  # stays ignored until the process exits
    assert signal.getsignal(signal.SIGINT) == signal.default_int_handler


def test_disarm_without_a_request_restores_the_previous_handlers(saved_handlers):
    def mine(signum, frame):
        raise RuntimeError

    signal.signal(signal.SIGTERM, mine)
    stop = StopRequest()
    stop.arm()
    assert signal.getsignal(signal.SIGTERM) != mine
    stop.disarm()
    assert signal.getsignal(signal.SIGTERM) is mine and not stop.requested


def test_second_ctrl_c_while_a_checkpoint_is_written_stops_once_it_is_in_place(saved_handlers, capsys, tmp_path):
    # a KeyboardInterrupt inside torch.save leaves torch's zip writer raising a RuntimeError ("unexpected pos"),
    # reported as a bug and losing the stop's checkpoint: the second Ctrl-C waits for the file instead
    import torch

    from ovon.train.checkpoint import atomic_torch_save

    signal.signal(signal.SIGINT, signal.default_int_handler)
    stop = StopRequest()
    stop.arm()
    _deliver(signal.SIGTERM)
    path = tmp_path / "checkpoint.pt"
    with pytest.raises(KeyboardInterrupt):
        with stop.writing():
            _deliver(signal.SIGINT)
            _deliver(signal.SIGINT)  # a third: still one message, still waits
            atomic_torch_save({"w": torch.arange(4)}, path)
            written = True
    assert written and torch.load(path)["w"].tolist() == [0, 1, 2, 3]
    assert capsys.readouterr().err.count("stopping once the checkpoint being written is in place") == 1
    with pytest.raises(KeyboardInterrupt):  # outside a write, a Ctrl-C stops at once again
        _deliver(signal.SIGINT)
    stop.disarm()


def test_a_write_without_a_stop_request_passes_through(saved_handlers):
    stop = StopRequest()
    stop.arm()
    with stop.writing():
        pass
    assert not stop.requested
    stop.disarm()
