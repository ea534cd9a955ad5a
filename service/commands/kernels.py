"""The integration kernels of a one-shot command, run in a helper process that loads them while the command
loads the rest.

A cold ``moi identify`` spends most of its time importing: scipy for the fit, numba and the registries it
builds before it can load even a cached kernel. Both are needed and neither needs the other, so the command
starts this helper first (``python -m service.commands.kernels KIND``): it loads numba and the rig kind's
cached kernel on another core while the command imports scipy, reads the trace and sets up the fit; then it
integrates each trajectory the fit asks for (``measurement.integrator.use_kernels``). The same compiled kernel
runs either way, so the results are bit for bit those of the in-process kernel.

Only with a kernel already compiled (a first run compiles in-process, as before) and with a core idle to
run on (on a busy machine the helper's own start would only add to the command's); if the helper cannot
start or dies, the command falls back to the in-process kernel.

Protocol: pickles on the helper's stdin and stdout, one request (kind and the ``run`` arguments without its
two outputs) and one answer ("ok", θ, θ') or ("error", text) at a time.
"""

from __future__ import annotations

import os
import pickle
import subprocess
import sys
import threading
from typing import IO, Any


class KernelHelper:
    """The command's side: a kernel source for ``measurement.integrator.use_kernels`` that sends each
    integration to the helper process (one at a time: candidate fits on threads take turns)."""

    def __init__(self, kinds: tuple[str, ...]) -> None:
        self.kinds = kinds
        self._lock = threading.Lock()
        self._proc: subprocess.Popen | None = subprocess.Popen(
            [sys.executable, "-m", __name__, *kinds], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL)

    def __call__(self, kind: str) -> Any:
        """The kernel of ``kind``: the helper's, or the in-process one once the helper is gone."""
        if kind not in self.kinds or self._proc is None:
            return self._in_process(kind)
        return _Remote(self, kind)

    def _in_process(self, kind: str) -> Any:
        from measurement.integrator import kernel
        return kernel(kind)

    def run(self, kind: str, args: tuple, out_x: Any, out_v: Any) -> None:
        with self._lock:
            proc = self._proc
            if proc is not None:
                try:
                    assert proc.stdin is not None and proc.stdout is not None
                    pickle.dump((kind, *args), proc.stdin, protocol=pickle.HIGHEST_PROTOCOL)
                    proc.stdin.flush()
                    answer = pickle.load(proc.stdout)
                except (OSError, EOFError, pickle.UnpicklingError):
                    answer = None
                if answer is not None and answer[0] == "ok":
                    out_x[:] = answer[1]
                    out_v[:] = answer[2]
                    return
                self._close_locked()  # the helper died or failed: the kernel runs here from now on
        self._in_process(kind).run(*args, out_x, out_v)

    def close(self) -> None:
        with self._lock:
            self._close_locked()

    def _close_locked(self) -> None:
        proc, self._proc = self._proc, None
        if proc is None:
            return
        for stream in (proc.stdin, proc.stdout):
            try:
                if stream is not None:
                    stream.close()
            except OSError:
                pass
        # it ends at the end of its input, or, still loading when the command ends early (a bad trace), now
        proc.kill()
        proc.wait()


class _Remote:
    """Stands for a kernel module: ``run`` with the compiled kernel's arguments."""

    def __init__(self, helper: KernelHelper, kind: str) -> None:
        self.helper = helper
        self.kind = kind

    def run(self, t: Any, x0: float, v0: float, w2: float, params: Any, holding: bool, max_step: float,
            out_x: Any, out_v: Any) -> None:
        self.helper.run(self.kind, (t, x0, v0, w2, params, holding, max_step), out_x, out_v)


def spare_core() -> bool:
    """Whether a core is idle for the helper besides the command's own: counted by the tasks running right now
    (Linux's /proc/loadavg, the command among them), else by the 1-min load average. On a busy machine the
    helper would only add its own start to the command's (it has no core to itself)."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    try:
        with open("/proc/loadavg", encoding="ascii") as f:
            others = float(f.read().split()[3].split("/")[0]) - 1
    except (OSError, ValueError, IndexError):
        others = os.getloadavg()[0]
    return cores - others >= 2


def start(kinds: tuple[str, ...]) -> KernelHelper | None:
    """The helper for these rig kinds, when it can help: each kernel compiled already (else the command
    compiles in-process, as before) and a core idle to run it on."""
    if not spare_core():
        return None
    from measurement.integrator import is_compiled
    if not all(is_compiled(k) for k in kinds):
        return None
    try:
        return KernelHelper(kinds)
    except OSError:
        return None


def serve(kinds: list[str], inp: IO[bytes], out: IO[bytes]) -> None:
    """The helper's side: load the kernels, then answer requests until the input ends."""
    # numba loads scipy (its BLAS, for linear algebra) and cffi (for CFFI functions) when they are installed,
    # and does without them when not; the kernels use neither, so this process goes without: half its start
    for optional in ("scipy", "cffi"):
        sys.modules.setdefault(optional, None)  # type: ignore[arg-type]
    import numpy as np

    from measurement.integrator import kernel, warm_up

    for kind in kinds:
        warm_up(kind)
    while True:
        try:
            kind, t, x0, v0, w2, params, holding, max_step = pickle.load(inp)
        except EOFError:
            return
        x = np.empty(t.size)
        v = np.empty(t.size)
        try:
            kernel(kind).run(t, x0, v0, w2, params, holding, max_step, x, v)
            answer: tuple = ("ok", x, v)
        except Exception as exc:  # the command then runs the kernel itself and raises there
            answer = ("error", f"{type(exc).__name__}: {exc}")
        pickle.dump(answer, out, protocol=pickle.HIGHEST_PROTOCOL)
        out.flush()


if __name__ == "__main__":
    serve(sys.argv[1:], sys.stdin.buffer, sys.stdout.buffer)
