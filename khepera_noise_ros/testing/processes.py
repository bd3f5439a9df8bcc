"""Process trees from /proc, for the tests that kill commands and look for what is left."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Callable


def start_time(pid: int) -> int | None:
    """The process's start time in clock ticks (tells it from a later one with the same pid),
    or None once it is gone or a zombie."""
    try:
        fields = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()
    except OSError:
        return None
    return None if fields[0] in ('Z', 'X') else int(fields[19])


def cpu_seconds(pid: int) -> float:
    """CPU time the process has used so far (0 once it is gone)."""
    try:
        fields = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()
    except OSError:
        return 0.0
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def opened(pid: int, name: str) -> bool:
    """Does the process hold a descriptor on ``name`` (say /dev/ptmx)?"""
    for fd in Path(f'/proc/{pid}/fd').glob('*'):
        try:
            if os.readlink(fd) == name:
                return True
        except OSError:
            pass
    return False


def children(pid: int) -> list[int]:
    found = []
    for task in Path(f'/proc/{pid}/task').glob('*'):
        try:
            found += [int(c) for c in (task / 'children').read_text().split()]
        except OSError:
            pass
    return found


def descendants(pid: int) -> dict[int, int]:
    """Every process below ``pid``: {pid: start time}."""
    found, todo = {}, children(pid)
    while todo:
        p = todo.pop()
        t = start_time(p)
        if t is not None and p not in found:
            found[p] = t
            todo += children(p)
    return found


def alive(recorded: dict[int, int]) -> dict[int, str]:
    """Those of ``recorded`` still running (same pid, same start time): {pid: command line}."""
    left = {}
    for pid, t in recorded.items():
        if start_time(pid) == t:
            try:
                left[pid] = Path(f'/proc/{pid}/cmdline').read_bytes().replace(b'\0', b' ') \
                    .decode(errors='replace')[:200]
            except OSError:
                continue
    return left


def wait_until(condition: Callable[[], object], timeout: float, poll: float = 0.05):
    """Poll ``condition`` until it is truthy (returned) or ``timeout`` passes (None)."""
    deadline = time.monotonic() + timeout
    while True:
        value = condition()
        if value or time.monotonic() > deadline:
            return value or None
        time.sleep(poll)


def env(domain: int, **extra) -> dict[str, str]:
    return dict(os.environ, ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST',
                PYTHONUNBUFFERED='1', **extra)


def command(*args: str) -> list[str]:
    return [sys.executable, '-m', 'khepera_noise_ros.cli', *args]


def start(args: list[str], domain: int, **kwargs) -> subprocess.Popen:
    """``args`` on ROS domain ``domain``, in the current directory unless ``cwd`` is given."""
    kwargs = {'stdout': subprocess.PIPE, 'stderr': subprocess.PIPE, **kwargs}
    return subprocess.Popen(args, env=env(domain), text=True, **kwargs)


def stop(proc: subprocess.Popen, how: int, timeout: float = 10.0) -> tuple[int | None, float]:
    """Send ``how`` and wait for the exit: (exit status or None if still running, seconds)."""
    sent = time.monotonic()
    proc.send_signal(how)
    try:
        code = proc.wait(timeout)
    except subprocess.TimeoutExpired:
        return None, time.monotonic() - sent
    return code, time.monotonic() - sent


def kill(proc: subprocess.Popen) -> None:
    """SIGKILL ``proc`` if it still runs, reap it and close its pipes."""
    with proc:
        if proc.poll() is None:
            proc.send_signal(signal.SIGKILL)
