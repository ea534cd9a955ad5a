"""The web page's child process (exports, plots) and multiprocessing's resource tracker end with the daemon,
however it ends: after a kill -9 (outside systemd, nothing else collects them) neither stays behind for a
restart loop to pile up."""

from __future__ import annotations

import json
import os
import select
import signal
import subprocess
import sys

from tests.service.conftest import REPO

DAEMON = """
import json, os, sys
from multiprocessing import resource_tracker
from service.publish.web.child import ChildWork

work = ChildWork()
worker = work.call(os.getpid)
print(json.dumps({"worker": worker, "tracker": resource_tracker._resource_tracker._pid}), flush=True)
sys.stdin.read()  # until killed
"""


def _ended(pid: int, timeout: float) -> bool:
    """True once process ``pid`` (not our child) has ended, waiting at most ``timeout`` s for it."""
    try:
        fd = os.pidfd_open(pid)
    except ProcessLookupError:
        return True
    try:
        return bool(select.select([fd], [], [], timeout)[0])
    finally:
        os.close(fd)


def test_the_child_and_the_resource_tracker_end_when_the_daemon_is_killed():
    daemon = subprocess.Popen([sys.executable, "-c", DAEMON], cwd=REPO, stdin=subprocess.PIPE,
                              stdout=subprocess.PIPE, text=True)
    assert daemon.stdin is not None and daemon.stdout is not None
    try:
        pids = json.loads(daemon.stdout.readline())
        assert pids["worker"] != daemon.pid and pids["tracker"] not in (None, daemon.pid)
        assert not _ended(pids["worker"], 0) and not _ended(pids["tracker"], 0)  # running beside the daemon
    finally:
        daemon.send_signal(signal.SIGKILL)
        daemon.wait(30)
        daemon.stdin.close()
        daemon.stdout.close()
    ended = {what: _ended(pid, 30) for what, pid in pids.items()}
    for what, pid in pids.items():
        if not ended[what]:
            os.kill(pid, signal.SIGKILL)  # an orphan: not left behind by the test
    assert ended == {"worker": True, "tracker": True}
