"""No orphans: whatever a command or node starts ends when it ends, even by SIGKILL."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
import yaml

from khepera_noise_ros.testing.domains import next_domain_id
from khepera_noise_ros.testing.processes import alive, command, descendants, kill, start, \
    wait_until

ROOT = Path(__file__).resolve().parents[2]

TINY = {'trials': 2, 'test_episodes': 2, 'phase1': {'population': 4, 'generations': 2000},
        'phase2': {'population': 3, 'generations': 200}, 'task': {'steps': 10},
        'reality': {'robots': 4}}


def run_parent(code: str) -> tuple[subprocess.Popen, int]:
    """A Python process running ``code``, which prints a child's pid; (process, that pid)."""
    parent = subprocess.Popen([sys.executable, '-c', textwrap.dedent(code)], cwd=ROOT,
                              stdout=subprocess.PIPE, text=True)
    line = parent.stdout.readline()
    assert line.strip().isdigit(), f'no child pid from the parent: {line!r}'
    return parent, int(line)


def assert_ends_with_parent(parent: subprocess.Popen, child: int) -> None:
    recorded = descendants(parent.pid)
    assert child in recorded, f'{child} is not below {parent.pid}: {recorded}'
    kill(parent)
    left = wait_until(lambda: not alive(recorded), 10)
    assert left, f'left behind after SIGKILL of the parent: {alive(recorded)}'


@pytest.mark.parametrize('how', ['prctl', 'poll'])
def test_a_forked_child_ends_when_its_parent_is_killed(how):
    parent, child = run_parent(f"""
        import multiprocessing, os, sys, time
        from khepera_noise_ros import lifeline
        if {how!r} == 'poll':                     # as where prctl is missing
            lifeline._prctl_deathsig = lambda sig: False
        def serve(parent, conn):
            conn.send(lifeline.die_with_parent(parent))
            time.sleep(120)
        a, b = multiprocessing.Pipe()
        p = multiprocessing.get_context('fork').Process(target=serve, args=(os.getpid(), b))
        p.start()
        assert a.recv() == {how!r}
        print(p.pid, flush=True)
        time.sleep(120)
        """)
    assert_ends_with_parent(parent, child)


def test_a_child_whose_parent_died_before_it_was_tied_ends_at_once():
    """The race: the parent was gone (the child re-parented) before prctl took effect."""
    code = ('import os, signal; from khepera_noise_ros import lifeline; '
            'lifeline.die_with_parent(os.getppid() + 1); print("survived")')
    done = subprocess.run([sys.executable, '-c', code], cwd=ROOT, capture_output=True,
                          text=True, timeout=60)
    assert done.returncode == -signal.SIGKILL and 'survived' not in done.stdout


def test_a_command_started_with_popen_ends_when_its_parent_is_killed():
    parent, child = run_parent("""
        import time
        from khepera_noise_ros import lifeline
        print(lifeline.popen(['sleep', '120']).pid, flush=True)
        time.sleep(120)
        """)
    assert_ends_with_parent(parent, child)


def test_popen_starts_nothing_once_its_parent_is_gone():
    """The wrapper checks that the pid it was given is still its parent before exec."""
    from khepera_noise_ros import lifeline
    proc = subprocess.Popen([sys.executable, '-S', '-c', lifeline._EXEC, '1', '9', 'sleep',
                             '120'])
    try:
        assert proc.wait(30) == 1
    finally:
        kill(proc)


def commands(tmp_path) -> dict[str, tuple[list[str], bool]]:
    """Each command that runs for long: (command line, whether it starts processes)."""
    tiny = tmp_path / 'tiny.yaml'
    tiny.write_text(yaml.safe_dump(TINY))
    return {
        'replicate': (command('replicate', '--config', str(tiny), '--out',
                              str(tmp_path / 'rep'), '--no-progress'), True),
        'emulate': (command('emulate', '--robots', '2'), False),
        'record': (command('record', str(tmp_path / 'rec'), '--robot', 'emulator',
                           '--samples', '5000', '--pace', '--period', '0.01'), False),
        'graph-evolve': (command('graph-evolve', '--population', '6', '--generations', '500',
                                 '--steps', '10', '--results', str(tmp_path / 'g.json')),
                         False),
        'bench_graph': ([sys.executable, 'benchmark/bench_graph.py', '--batches', '2',
                         '--pairs', '1', '2', '--seconds', '5', '--steps', '10'], True),
    }


@pytest.mark.parametrize('name', ['replicate', 'emulate', 'record', 'graph-evolve',
                                  'bench_graph'])
def test_sigkill_of_a_command_leaves_none_of_its_processes(name, tmp_path):
    args, spawns = commands(tmp_path)[name]
    proc = start(args, next_domain_id(), cwd=ROOT)
    try:
        # running: its children started (and had a moment to start theirs), or some output
        if spawns:
            assert wait_until(lambda: descendants(proc.pid) or proc.poll() is not None, 60)
            wait_until(lambda: proc.poll() is not None, 1)
        else:
            wait_until(lambda: proc.poll() is not None, 4)
        assert proc.poll() is None, f'{name} ended early: {proc.communicate()[1][-2000:]}'
        recorded = descendants(proc.pid)
        assert bool(recorded) == spawns, recorded
        proc.send_signal(signal.SIGKILL)
        proc.wait(10)
        assert wait_until(lambda: not alive(recorded), 10), \
            f'{name} left behind after SIGKILL: {alive(recorded)}'
    finally:
        for pid in alive(recorded if 'recorded' in locals() else {}):
            os.kill(pid, signal.SIGKILL)            # what it left behind
        kill(proc)


def test_a_sigterm_inside_rclpy_s_future_callbacks_is_sent_again_not_raised_there(
        monkeypatch):
    """Raised inside rclpy's task machinery the interrupt would be logged as a failed
    callback with its traceback; it is sent again a moment later instead."""
    import threading
    from khepera_noise_ros import lifeline
    space: dict = {}
    exec(compile('import sys\nframe = sys._getframe()', os.path.join('rclpy', 'task.py'),
                 'exec'), space)
    sent = threading.Event()
    monkeypatch.setattr(os, 'kill', lambda pid, sig: sent.set()
                        if (pid, sig) == (os.getpid(), signal.SIGTERM) else None)
    with lifeline.terminate_as_interrupt():
        handler = signal.getsignal(signal.SIGTERM)
        handler(signal.SIGTERM, space['frame'])          # inside rclpy/task.py: no raise
        assert sent.wait(2.0)
        with pytest.raises(KeyboardInterrupt):
            handler(signal.SIGTERM, sys._getframe())      # anywhere else: as Ctrl-C


def test_a_stop_signal_inside_a_finalizer_is_sent_again_not_raised_there(monkeypatch):
    """Raised inside a ``__del__`` (the garbage collector runs one anywhere, rclpy's
    loggers have one) the interrupt would be printed as "Exception ignored" and dropped,
    and the command would run on to its end; it is sent again a moment later instead,
    SIGTERM and Ctrl-C alike."""
    import threading
    from khepera_noise_ros import lifeline
    frames = []

    class Finalized:
        def __del__(self):
            frames.append(sys._getframe())
    Finalized()
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        for sig in (signal.SIGTERM, signal.SIGINT):
            sent = threading.Event()
            monkeypatch.setattr(os, 'kill', lambda pid, s, sig=sig: sent.set()
                                if (pid, s) == (os.getpid(), sig) else None)
            with lifeline.terminate_as_interrupt():
                try:
                    signal.getsignal(sig)(sig, frames[0])
                except KeyboardInterrupt:
                    pytest.fail(f'{sig!r} raised inside the finalizer, where it is dropped')
                assert sent.wait(2.0), sig
                with pytest.raises(KeyboardInterrupt):
                    signal.getsignal(sig)(sig, sys._getframe())    # anywhere else: Ctrl-C
            assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    finally:
        signal.signal(signal.SIGINT, previous)


def test_an_ignored_ctrl_c_stays_ignored_inside():
    from khepera_noise_ros import lifeline
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        with lifeline.terminate_as_interrupt():
            assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGINT, previous)
