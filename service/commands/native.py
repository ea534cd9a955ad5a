"""The integration kernels of a one-shot command as a native extension module: no numba in the command.

numba is most of a cold ``moi identify``: importing it and the registries it fills before it can run even a
cached kernel costs ~0.45 s of CPU here, the kernel's own work ~0.05 s. ``numba.pycc`` compiles the same
generated kernel (``measurement.integrator.kernel_source``, the ``run`` that the in-process kernel runs, with
its flags) ahead of time into an extension module that needs only numpy; the command imports it in a
millisecond. Same source, same LLVM code generation without fast-math: the results are bit for bit those of
the in-process kernel (test).

The module is built once per effect library, Python and cache folder, in a process of its own at low
priority (``python -m service.commands.native KIND...``), which the first command that finds it missing
starts in the background and does not wait for: that command and any run before the build ends use the
in-process kernel, as before. The build needs numba, setuptools and a C compiler; without them, or on a
module that does not load (a numpy whose ABI changed, a cache folder mounted noexec), the command goes on
with the in-process kernel, and the failure is written beside the module (``*.failed``, its error inside):
no command starts that build again until the effect library changes or the file is deleted.

A module is loaded only when it is the one that was built: the build writes its size and SHA-256 beside it
(``*.sha256``) once the compiler has finished, before the module takes its place. A module that differs (cut
short by a power failure while it was written, a bad SD card), or has no such record, is never mapped: the
dynamic loader would fault (SIGBUS) on pages the file no longer has, killing the command without a word. It
is deleted instead, the command uses the in-process kernel, and the next background build replaces it.

The native kernel holds the interpreter lock while it runs (pycc has no ``nogil``): candidate fits on
threads take turns. It is for one-shot commands only; the daemon keeps the in-process kernel, which lets a
capture run beside a fit.
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib.machinery
import importlib.util
import json
import os
import shutil
import subprocess
import sys
import tempfile
import warnings
from pathlib import Path
from types import ModuleType
from typing import Any

#: the ``run`` of the generated kernel as numba types: contiguous float64 arrays, as ``Dynamics.integrate`` passes
SIGNATURE = "void(f8[::1], f8, f8, f8, f8[::1], b1, f8, f8[::1], f8[::1])"

#: builders started by this process (held so that one still running at exit is not reported as leaked)
_BUILDERS: list[subprocess.Popen] = []


def module_file(kind: str) -> Path:
    """Where the ``kind`` native kernel lives: beside its generated source, named by the same hash."""
    from measurement.integrator import kernel_file

    src = kernel_file(kind)
    return src.with_name(f"{src.stem}_native{importlib.machinery.EXTENSION_SUFFIXES[0]}")


def _failed(kind: str) -> Path:
    """A build of the ``kind`` native kernel failed here (its error inside): no new attempt for this library."""
    return module_file(kind).with_suffix(".failed")


def _stamp(kind: str) -> Path:
    """The size and SHA-256 of the ``kind`` native kernel as its build wrote it."""
    return module_file(kind).with_suffix(".sha256")


def _fingerprint(path: Path) -> dict[str, Any]:
    # read, never mapped: reading a file cut short ends early, mapping it faults
    digest = hashlib.sha256()
    size = 0
    with path.open("rb") as f:
        while chunk := f.read(1 << 20):
            digest.update(chunk)
            size += len(chunk)
    return {"size": size, "sha256": digest.hexdigest()}


def intact(kind: str) -> bool:
    """Whether the ``kind`` native kernel on disk is, byte for byte, the module its build wrote down."""
    path = module_file(kind)
    try:
        stamp = json.loads(_stamp(kind).read_text())
        if path.stat().st_size != stamp.get("size"):  # a cut-short file is told before reading it
            return False
        return _fingerprint(path) == {"size": stamp["size"], "sha256": stamp.get("sha256")}
    except (OSError, ValueError, AttributeError, KeyError):  # no record, an unreadable or a damaged one
        return False


def _discard(kind: str) -> None:
    """Delete a damaged native kernel and its record: the next ``build_later`` builds it again."""
    for path in (module_file(kind), _stamp(kind)):
        with contextlib.suppress(OSError):  # a read-only cache: the module stays unloaded all the same
            path.unlink(missing_ok=True)


def _load(kind: str) -> ModuleType | None:
    path = module_file(kind)
    if not path.exists():
        return None
    if not intact(kind):
        _discard(kind)
        return None
    name = path.name.split(".", 1)[0]  # the extension's init function is named after it
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        return None
    try:
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
    except ImportError as exc:
        # another numpy's ABI, or a cache folder mounted noexec: written down as a failed build, so that
        # commands do not rebuild what would not load either
        _write_failure(kind, exc)
        _discard(kind)
        return None
    return mod


def _write_failure(kind: str, exc: BaseException) -> None:
    with contextlib.suppress(OSError):  # a read-only cache: nothing to remember it in
        _failed(kind).write_text(f"{type(exc).__name__}: {exc}\n")


class NativeKernels:
    """A kernel source for ``measurement.integrator.use_kernels``: each rig kind's native module."""

    def __init__(self, modules: dict[str, ModuleType]) -> None:
        self.modules = modules

    def __call__(self, kind: str) -> Any:
        mod = self.modules.get(kind)
        if mod is None:  # a kind the command did not load: the in-process kernel
            from measurement.integrator import kernel
            return kernel(kind)
        return mod

    def close(self) -> None:
        """Nothing to stop (the same interface as ``kernels.KernelHelper``)."""


def load(kinds: tuple[str, ...]) -> NativeKernels | None:
    """The native kernels of these rig kinds, when every one is built and loads; else None."""
    modules = {}
    for kind in kinds:
        mod = _load(kind)
        if mod is None:
            return None
        modules[kind] = mod
    return NativeKernels(modules)


def build_later(kinds: tuple[str, ...]) -> None:
    """Start building the missing native kernels of these kinds in the background, unless a build is under way.

    The lock is a ``flock`` the builder inherits: the kernel lets it go when the builder ends, however it ends.
    """
    _BUILDERS[:] = [p for p in _BUILDERS if p.poll() is None]  # the ended ones reaped
    missing = [k for k in kinds if not module_file(k).exists() and not _failed(k).exists()]
    if not missing:
        return
    try:
        import fcntl
    except ImportError:  # not on a POSIX system: no background build
        return
    try:
        fd = os.open(module_file(missing[0]).parent / ".native-build.lock", os.O_RDWR | os.O_CREAT, 0o644)
    except OSError:
        return
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        _BUILDERS.append(subprocess.Popen(
            [sys.executable, "-m", __name__, *missing], stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL, start_new_session=True, pass_fds=(fd,)))
    except OSError:  # a build under way holds the lock, or no process could start: the next command tries
        pass
    finally:
        os.close(fd)  # the builder's copy keeps the lock


def build(kind: str) -> Path:
    """Compile the ``kind`` native kernel into the cache (seconds to a minute; needs numba, setuptools and
    a C compiler) and return its path."""
    from measurement.integrator import kernel

    inner = kernel(kind).run  # the in-process kernel's compiled run, with its flags (error model, inlining)

    def run(t, x0, v0, w2, P, holding, max_step, out_x, out_v):
        inner(t, x0, v0, w2, P, holding, max_step, out_x, out_v)

    target = module_file(kind)
    work = Path(tempfile.mkdtemp(prefix=".native-", dir=target.parent))
    previous = tempfile.tempdir
    try:
        tempfile.tempdir = str(work)  # pycc's own build folder, removed with ours whatever happens
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # pycc's pending deprecation: a missing pycc is met by the fallback
            from numba.pycc import CC
        cc = CC(target.name.split(".", 1)[0])
        cc.output_dir = str(work)
        cc.export("run", SIGNATURE)(run)
        cc.compile()
        built = next(work.glob(f"{target.name.split('.', 1)[0]}*{importlib.machinery.EXTENSION_SUFFIXES[0]}"))
        _durable(built)
        # the record first, then the module: a module in place always has its record, and a power cut between
        # the two leaves a record without a module, which is built again
        record = work / "stamp"
        record.write_text(json.dumps(_fingerprint(built)))
        _durable(record)
        os.replace(record, _stamp(kind))
        os.replace(built, target)  # whole or not at all: a command never loads half a file
    finally:
        tempfile.tempdir = previous
        shutil.rmtree(work, ignore_errors=True)
    return target


def _durable(path: Path) -> None:
    """On the disk, not only in the page cache, before a rename makes it visible."""
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def main(kinds: list[str]) -> int:
    """Build each kind's native kernel; a failure is written down so that commands stop starting builds."""
    status = 0
    for kind in kinds:
        try:
            build(kind)
        except Exception as exc:  # no compiler, no setuptools, no pycc: the in-process kernel it stays
            _write_failure(kind, exc)
            print(f"native kernel {kind}: {type(exc).__name__}: {exc}", file=sys.stderr)
            status = 1
    return status


if __name__ == "__main__":
    os.nice(10)  # behind whatever the machine measures meanwhile
    sys.exit(main(sys.argv[1:]))
