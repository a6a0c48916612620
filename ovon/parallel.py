"""Fan-out of independent jobs: in-process, worker processes (default) or Ray tasks (clusters).

Results come back as jobs finish (so callers can write them out incrementally); a `rich` progress bar
counts finished jobs.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable, Iterator
from typing import Any


def init_worker() -> None:
    """One thread per worker: a 2-thread process slows 3-4x when another process holds a core."""
    os.environ.setdefault("OMP_NUM_THREADS", "1")  # honoured by torch when a job imports it later
    os.environ.setdefault("LP_NUM_THREADS", "0")  # llvmpipe renders in-thread: one process per core scales
    torch = sys.modules.get("torch")  # importing torch only for this would cost seconds per worker
    if torch is not None:
        torch.set_num_threads(1)


def run_jobs(fn: Callable[[Any], Any], jobs: list, workers: int = 1, executor: str = "process") -> Iterator[Any]:
    """Yield `fn(job)` results in completion order. `fn` must be a module-level function."""
    if not jobs:
        return
    if executor == "ray":
        import ray

        if not ray.is_initialized():
            ray.init(address=os.environ.get("RAY_ADDRESS") or None, include_dashboard=False,
                     log_to_driver=False)
        remote = ray.remote(num_cpus=1)(fn)
        pending = [remote.remote(j) for j in jobs]
        while pending:
            ready, pending = ray.wait(pending, num_returns=1)
            yield ray.get(ready[0])
        return
    if executor != "process":
        raise ValueError(f"unknown executor {executor!r}: use process or ray")
    if workers <= 1 or len(jobs) == 1:
        for j in jobs:
            yield fn(j)
        return
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor, as_completed

    with ProcessPoolExecutor(min(workers, len(jobs)), mp_context=mp.get_context("spawn"),
                             initializer=init_worker) as pool:
        futures = [pool.submit(fn, j) for j in jobs]
        for f in as_completed(futures):
            yield f.result()


def progress_bar(description: str, total: int, enabled: bool = True):
    """A rich progress context whose `.advance(n)` is a no-op when disabled."""
    from contextlib import nullcontext

    if not enabled:
        class _Null:
            def advance(self, n: int = 1) -> None:
                pass

        return nullcontext(_Null())
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeElapsedColumn, TimeRemainingColumn

    class _Bar:
        def __init__(self) -> None:
            self.p = Progress("[bold]{task.description}", BarColumn(), MofNCompleteColumn(),
                              TimeElapsedColumn(), TimeRemainingColumn())
            self.t = self.p.add_task(description, total=total)

        def __enter__(self):
            self.p.__enter__()
            return self

        def __exit__(self, *exc):
            return self.p.__exit__(*exc)

        def advance(self, n: int = 1) -> None:
            self.p.advance(self.t, n)

    return _Bar()
