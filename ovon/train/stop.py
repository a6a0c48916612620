"""A stop request that a training loop honours at the end of its current update, with a checkpoint.

Why: without it, Ctrl-C or SIGTERM (`kill`, `timeout`, a scheduler, `ovon experiment run` stopping its
child) ends `ovon train` at once and the updates since the last scheduled checkpoint (up to
`checkpoint_every`, minutes at cpu scale) are lost. With it, the first Ctrl-C or SIGTERM lets the
current update finish, writes a checkpoint of it and exits as an interrupt (exit 130), so `--resume`
continues from the update where it stopped, to the weights of an uninterrupted run. A second Ctrl-C
stops at once (the last scheduled checkpoint stands), except while a checkpoint is being written
(`writing()`): then it stops as soon as the file is in place, since a KeyboardInterrupt inside
`torch.save` surfaces as torch's zip-writer RuntimeError, reported as a bug, and throws away the
checkpoint that makes the resume lose nothing. Further SIGTERMs are ignored (a process group's stop
followed by the runner's own must not cut the checkpoint short).
"""

from __future__ import annotations

import signal
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

_SIGNALS = (signal.SIGINT, signal.SIGTERM)


class StopRequest:
    """Installed by `arm()` for the update loop (main thread only; elsewhere signals keep their
    handlers and `requested` stays False); `disarm()` puts the previous handlers back."""

    def __init__(self) -> None:
        self.requested = False
        self._previous: dict[int, Any] = {}
        self._writing = False
        self._stop_now = False

    def arm(self) -> None:
        try:
            for s in _SIGNALS:
                self._previous[s] = signal.signal(s, self._handle)
        except ValueError:  # not the main thread
            self._restore()

    def _handle(self, signum: int, frame) -> None:
        if self.requested:
            if signum != signal.SIGINT:
                return
            if not self._writing:  # a second Ctrl-C: stop now
                raise KeyboardInterrupt
            if not self._stop_now:
                self._stop_now = True
                print("ovon: stopping once the checkpoint being written is in place", file=sys.stderr, flush=True)
            return
        self.requested = True
        print(
            "ovon: stopping after this update, with a checkpoint (Ctrl-C again to stop now)",
            file=sys.stderr,
            flush=True,
        )

    @contextmanager
    def writing(self) -> Iterator[None]:
        """Hold a second Ctrl-C while a checkpoint is written; it stops the run once the file is in place."""
        self._writing = True
        try:
            yield
        finally:
            self._writing = False
        if self._stop_now:
            raise KeyboardInterrupt

    def disarm(self) -> None:
        if not self._previous:
            return
        self._restore()
        if self.requested:  # as `ovon.cli.main` does after its first SIGTERM: ignored until the exit
            try:
                signal.signal(signal.SIGTERM, signal.SIG_IGN)
            except ValueError:
                pass

    def _restore(self) -> None:
        for s, handler in self._previous.items():
            if signal.getsignal(s) == self._handle:
                signal.signal(s, handler)
        self._previous = {}
