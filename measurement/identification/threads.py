"""The identification's threads: independent candidate fits side by side, and BLAS held to one thread.

Threads, not processes: the integrator's compiled kernel and the BLAS calls
release the GIL, and threads cost no start-up, no pickling and no second copy
of numpy, scipy and the kernels in memory. The matrices here are tall and thin
(samples × a few parameters): BLAS threads only contend with each other and
with the candidate fits' threads, on a busy machine by a factor of 30 for an SVD.
"""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from contextlib import AbstractContextManager
from functools import lru_cache
from typing import Any, Callable, Sequence, TypeVar

from threadpoolctl import ThreadpoolController

T = TypeVar("T")
R = TypeVar("R")


def usable_cores() -> int:
    """Cores this process may run on (a ``taskset`` or a container's CPU set counts)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def parallel_map(fn: Callable[[T], R], items: Sequence[T]) -> list[R]:
    """[fn(item) for item in items], on threads when more than one core is usable.

    Threads, not processes: the integrator's compiled kernel and the BLAS
    calls release the GIL, and threads cost no start-up, no pickling and no
    second copy of numpy, scipy and the kernels in memory. On one core the
    items run one after the other in this thread.
    """
    workers = min(len(items), usable_cores())
    if workers <= 1:
        return [fn(item) for item in items]
    with ThreadPoolExecutor(max_workers=workers, thread_name_prefix="moi-fit") as pool:
        return list(pool.map(fn, items))


def one_blas_thread() -> AbstractContextManager[Any]:
    """A context in which BLAS runs on one thread (the identification and the joint fit run in it)."""
    return _controller().limit(limits=1, user_api="blas")


@lru_cache(maxsize=1)
def _controller() -> ThreadpoolController:
    # finding the loaded BLAS libraries walks every shared object: once per process
    return ThreadpoolController()
