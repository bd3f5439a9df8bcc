"""The evolution manager checkpoints every generation and resumes an interrupted run."""
from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading

import numpy as np
import pytest
from rclpy.parameter import Parameter

from khepera_noise_ros.nodes.checkpoint import FORMAT, Checkpoint
from khepera_noise_ros.nodes.controller import Controller
from khepera_noise_ros.nodes.local_graph import local_graph
from khepera_noise_ros.nodes.runtime import events_executor, spinning
from khepera_noise_ros.testing.evolutions import CONFIG, SEED, STEPS, TRIALS, \
    assert_same_evolution, core_run
from khepera_noise_ros.testing.probe import controller, simulator, wait_for


class Crash(Exception):
    """Stands for the process dying."""


class Counted:
    """An evaluator that counts its batches, and crashes after ``crash_after`` of them."""

    def __init__(self, inner, crash_after: int | None = None):
        self.inner, self.crash_after, self.batches = inner, crash_after, 0

    def __call__(self, genomes, seeds):
        if self.batches == self.crash_after:
            raise Crash(f'crashed after {self.batches} batches')
        self.batches += 1
        return self.inner(genomes, seeds)

    def __getattr__(self, name):
        return getattr(self.inner, name)


def test_a_run_interrupted_after_any_batch_resumes_to_the_uninterrupted_result(
        ros_context, tmp_path):
    eas, done = core_run()
    results = tmp_path / 'run.json'
    checkpoint = tmp_path / 'run.checkpoint.json'
    with local_graph(ros_context, simulator={'steps': STEPS}, thread=False, trace=False,
                     executor_class=events_executor, manager={
                         'population': CONFIG.population, 'generations': CONFIG.generations,
                         'trials': TRIALS, 'seed': SEED, 'results_path': str(results)}) as graph:
        mgr, inner = graph.manager, graph.manager.evaluator
        inner.wait_ready()
        for crash_after in range(1, len(done)):
            mgr.evaluator = Counted(inner, crash_after)
            with pytest.raises(Crash):
                mgr.run()
            # the last checkpoint was written when the last generation completed
            saved = max(b for b in range(1, crash_after + 1)
                        if done[b - 1] > (done[b - 2] if b > 1 else 0))
            state = json.loads(checkpoint.read_text())
            assert state['format'] == FORMAT and len(state['batches']) == saved
            assert state['generation'] == done[saved - 1] - 1
            assert not results.exists()

            mgr.evaluator = Counted(inner)
            record = mgr.run()                  # resumes
            assert mgr.evaluator.batches == len(done) - saved, crash_after
            assert record['resumed'] == {'checkpoint': str(checkpoint), 'batches': saved,
                                         'generation': done[saved - 1] - 1}
            assert_same_evolution(record, eas)
            assert json.loads(results.read_text()) == record
            assert not checkpoint.exists()      # removed once the results are written
            results.unlink()


def test_another_run_s_settings_are_named_on_one_line_whatever_their_keys(tmp_path):
    """hypothesis found it: a config key holding a line break broke the one-line error."""
    path = tmp_path / 'run.checkpoint.json'
    path.write_text(json.dumps({'format': FORMAT, 'config': {'\n': False, 'seed': 3},
                                'batches': []}))
    with pytest.raises(ValueError) as refused:
        Checkpoint(path, {'seed': 4}).load()
    assert '\n' not in str(refused.value)
    assert 'it differs in \\n, seed)' in str(refused.value)


def test_a_checkpoint_of_another_run_is_refused_unless_resume_is_off(ros_context, tmp_path):
    checkpoint = tmp_path / 'mine.json'
    with local_graph(ros_context, simulator={'steps': STEPS}, thread=False, trace=False,
                     executor_class=events_executor, manager={
                         'population': CONFIG.population, 'generations': CONFIG.generations,
                         'trials': TRIALS, 'seed': SEED, 'results_path': '',
                         'checkpoint_path': str(checkpoint)}) as graph:
        mgr, inner = graph.manager, graph.manager.evaluator
        inner.wait_ready()
        mgr.evaluator = Counted(inner, crash_after=5)
        with pytest.raises(Crash):
            mgr.run()
        mgr.evaluator = inner
        assert mgr.set_parameters([Parameter('seed', value=SEED + 1)])[0].successful
        with pytest.raises(ValueError, match='belongs to another run .*differs in seed'):
            mgr.run()
        assert mgr.set_parameters([Parameter('resume', value=False)])[0].successful
        record = mgr.run()
    assert record['resumed'] is None
    assert_same_evolution(record, core_run(SEED + 1)[0])


class GatedController(Controller):
    """Answers only while ``open`` is set; ``held`` is set by a light it leaves unanswered."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.open, self.held = threading.Event(), threading.Event()
        self.open.set()

    def _on_light(self, msg):
        if self.open.is_set():
            super()._on_light(msg)
        else:
            self.held.set()


def test_the_manager_killed_by_sigkill_mid_run_resumes_with_no_generation_lost(
        ros_context, tmp_path):
    """The manager is a process of its own; it is killed in the middle of an episode after
    some generations, then started again with the same parameters."""
    results, checkpoint = tmp_path / 'killed.json', tmp_path / 'killed.checkpoint.json'
    env = dict(os.environ, ROS_DOMAIN_ID=str(ros_context.get_domain_id()),
               ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    command = [sys.executable, '-m', 'khepera_noise_ros.nodes.evolution_manager', '--ros-args',
               '-p', f'population:={CONFIG.population}',
               '-p', f'generations:={CONFIG.generations}', '-p', f'trials:={TRIALS}',
               '-p', f'seed:={SEED}', '-p', f'results_path:={results}',
               '-p', 'stall_timeout_s:=30.0', '-p', 'ready_timeout_s:=30.0']
    ctrl = controller(ros_context, cls=GatedController)
    eas, done = core_run()
    procs = []
    try:
        with spinning([simulator(ros_context, steps=STEPS, resend_timeout_s=0.05), ctrl],
                      ros_context):
            procs.append(subprocess.Popen(command, env=env, stderr=subprocess.DEVNULL))
            assert wait_for(lambda: checkpoint.exists()
                            and json.loads(checkpoint.read_text())['generation'] >= 1, 60), \
                'no checkpoint of generation 1'
            ctrl.open.clear()                     # the manager waits in the middle of a step
            assert ctrl.held.wait(30)
            procs[0].send_signal(signal.SIGKILL)
            assert procs[0].wait(10) == -signal.SIGKILL
            killed_at = json.loads(checkpoint.read_text())
            assert not results.exists()
            ctrl.open.set()

            procs.append(subprocess.Popen(command, env=env, stderr=subprocess.PIPE, text=True))
            _, err = procs[1].communicate(timeout=90)
            assert procs[1].returncode == 0, err[-3000:]
    finally:
        for proc in procs:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    record = json.loads(results.read_text())
    assert_same_evolution(record, eas)
    assert record['resumed']['generation'] == killed_at['generation'] >= 1     # none lost
    assert record['resumed']['batches'] == len(killed_at['batches'])
    assert f"resuming from checkpoint {checkpoint}: generation {killed_at['generation']}" in err
    assert not checkpoint.exists()
    assert np.isfinite(record['wall_time_s'])


def test_a_finished_run_removes_the_temporary_a_killed_writer_left(tmp_path):
    path = tmp_path / 'run.checkpoint.json'
    checkpoint = Checkpoint(path, {'seed': 1})
    checkpoint.save(generation=3)
    orphan = tmp_path / '.run.checkpoint.json.k1ll3d.tmp'    # as a SIGKILL mid-write leaves it
    orphan.write_text('{"format": ')
    other = tmp_path / '.results.json.abc.tmp'               # another file's: not ours to remove
    other.write_text('')
    checkpoint.remove()
    assert not path.exists() and not orphan.exists() and other.exists()
