"""Child processes that end when their parent ends, however the parent ends.

A process killed with SIGKILL runs no clean-up, so its children must notice by
themselves.  On Linux the kernel tells them: ``prctl(PR_SET_PDEATHSIG)`` sends a
signal to the child when its parent dies, and survives ``exec``.  Where that is
missing, a daemon thread in the child polls ``getppid()``.  Either way the
child checks once more right after arming, in case the parent died before.

Note: on Linux the death signal follows the *thread* that started the child,
so start children from a thread that lives as long as they should (the main
thread, everywhere in this package).
"""
from __future__ import annotations

import contextlib
import ctypes
import os
import signal
import subprocess
import sys
import threading
from types import FrameType

PR_SET_PDEATHSIG = 1
PARENT_ENV = 'KHEPERA_NOISE_PARENT_PID'   # the portable fallback for exec'd children
POLL_S = 0.25
RESEND_S = 0.02         # a SIGTERM that came where it would be dropped, sent again
TASK = os.path.join('rclpy', 'task.py')      # rclpy's future machinery

# Run by the child between fork and exec (see popen): arm the death signal, check the
# parent is still the one that started us, then become the command.  No package import.
_EXEC = ('import ctypes,os,sys\n'
         'p,s=int(sys.argv[1]),int(sys.argv[2])\n'
         'try:\n ctypes.CDLL(None,use_errno=True).prctl(1,s,0,0,0)\n'
         'except (OSError,AttributeError):\n pass\n'
         'if os.getppid()!=p:\n os._exit(1)\n'
         'os.execvp(sys.argv[3],sys.argv[3:])\n')


def _prctl_deathsig(sig: int) -> bool:
    """Ask the kernel for ``sig`` when the parent dies; False where prctl is missing."""
    if not sys.platform.startswith('linux'):
        return False
    try:
        return ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, int(sig), 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def _end(sig: int) -> None:
    os.kill(os.getpid(), sig)
    os._exit(1)                         # the signal was caught or ignored: end anyway


def _watch(parent: int, sig: int) -> None:
    def poll():
        while os.getppid() == parent:
            threading.Event().wait(POLL_S)
        _end(sig)
    threading.Thread(target=poll, name='lifeline', daemon=True).start()


def die_with_parent(parent: int, sig: int = signal.SIGKILL) -> str:
    """In a child, first thing: end with ``sig`` once process ``parent`` has gone.

    ``parent`` is the pid the parent had before it started the child (not
    ``getppid()`` read now: the parent may be dead already).  Returns how the
    child is tied: 'prctl' or 'poll'."""
    how = 'prctl' if _prctl_deathsig(sig) else 'poll'
    if os.getppid() != parent:          # died before the tie was made
        _end(sig)
    if how == 'poll':
        _watch(parent, sig)
    return how


def from_environment(sig: int = signal.SIGTERM) -> None:
    """In a program's main: where prctl is missing, watch the parent pid ``popen`` left in
    the environment (on Linux the death signal is armed already: a no-op)."""
    text = os.environ.pop(PARENT_ENV, '')
    if not text.isdigit() or sys.platform.startswith('linux'):
        return
    parent = int(text)
    if os.getppid() != parent:
        if _alive(parent):
            return                      # left by a grandparent: not ours to watch
        _end(sig)
    _watch(parent, sig)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        pass
    return True


def popen(args: list[str], sig: int = signal.SIGKILL, **kwargs) -> subprocess.Popen:
    """``subprocess.Popen(args, **kwargs)`` whose process ends when this one ends.

    The child runs a few lines of Python that arm the death signal and then
    ``exec`` the command, rather than a ``preexec_fn``, which is unsafe once
    DDS threads run in this process.  The pid is the command's."""
    parent = os.getpid()
    env = dict(kwargs.pop('env', None) or os.environ, **{PARENT_ENV: str(parent)})
    wrapped = [sys.executable, '-S', '-c', _EXEC, str(parent), str(int(sig)), *args]
    return subprocess.Popen(wrapped, env=env, **kwargs)


def _swallowed(frame: FrameType | None) -> bool:
    """Would an interrupt raised at ``frame`` be printed and dropped, not stop the command:
    inside rclpy's future machinery (logged as a failed done callback) or a finalizer
    (``__del__``, which the garbage collector runs anywhere: "Exception ignored")?"""
    while frame is not None:
        code = frame.f_code
        if code.co_name == '__del__' or code.co_filename.endswith(TASK):
            return True
        frame = frame.f_back
    return False


@contextlib.contextmanager
def terminate_as_interrupt():
    """While inside, SIGTERM stops the main thread as Ctrl-C does (``KeyboardInterrupt``),
    so a plain ``kill`` saves what Ctrl-C saves; either, landing where the interrupt would
    be dropped (``_swallowed``), is sent again a moment later (an ignored Ctrl-C stays so)."""
    def interrupt(signum, frame):
        if _swallowed(frame):
            threading.Timer(RESEND_S, os.kill, (os.getpid(), signum)).start()   # again soon
            return
        raise KeyboardInterrupt
    ours = [signal.SIGTERM]
    if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        ours.append(signal.SIGINT)
    try:
        previous = {sig: signal.signal(sig, interrupt) for sig in ours}
    except ValueError:                  # not the main thread: leave signals alone
        yield
        return
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
