"""The chaos run: a whole evolution over three worker-pair processes while a random worker is
SIGKILLed and restarted at each of a fixed list of generations and the manager is SIGKILLed
once and resumed.  The result must be the undisturbed one, no checkpoint ever half-written,
no process left.

The kills follow the evolution's progress (its checkpoints), not the clock, so that every
planned kill happens however fast the machine evolves or restarts a worker: one worker is
down at a time, and when a kill is due while the last victim is not yet back in the pool,
the manager is paused (SIGSTOP) until it is, then resumed (SIGCONT) -- one more disturbance
the result must not show."""
from __future__ import annotations

import json
import random
import signal
import subprocess
import sys
import time

from khepera_noise_ros.testing.domains import next_domain_id
from khepera_noise_ros.testing.processes import alive, descendants, env, start_time
from khepera_noise_ros import lifeline
from khepera_noise_ros.core import evolution
from khepera_noise_ros.core.evaluation import CoreEvaluator
from khepera_noise_ros.core.task import Task
from khepera_noise_ros.nodes.checkpoint import FORMAT

STEPS, SEED, TRIALS = 15, 16, 2
CONFIG = evolution.EAConfig(population=6, generations=160)
WORKERS = ['/chaos0', '/chaos1', '/chaos2']
WORKER_KILLS_AT = (10, 25, 55, 80, 105, 130)    # generations
MANAGER_KILL_AT = 40                             # generation
SETTLE_S = 3.0          # a restarted worker the manager never missed counts as back after this
DEADLINE_S = 240.0


def undisturbed() -> list[evolution.SteadyStateEA]:
    """The evolution as the core runs it (which equals an undisturbed graph run: see
    test_nodes_distributed and test_nodes_checkpoint)."""
    eas = [evolution.SteadyStateEA(CONFIG, SEED + i) for i in range(TRIALS)]
    evolution.evolve(eas, CoreEvaluator(task=Task(steps=STEPS)))
    return eas


class Cast:
    """The processes of the run, each started with a lifeline; every pid ever started is
    remembered (with its start time) to check at the end that none is left."""

    def __init__(self, tmp_path, domain: int):
        self.tmp, self.env, self.started = tmp_path, env(domain), {}
        self.workers: dict[str, subprocess.Popen] = {}
        self.since: dict[str, float] = {}
        self.mark: dict[str, int] = {}      # the manager's log length at the worker's start
        self.managers: list[subprocess.Popen] = []

    def _popen(self, args: list[str], log) -> subprocess.Popen:
        proc = lifeline.popen(args, sig=signal.SIGKILL, env=self.env,
                              stdout=subprocess.DEVNULL, stderr=log)
        self.started[proc.pid] = start_time(proc.pid)
        return proc

    def worker(self, ns: str) -> None:
        self.since[ns] = time.monotonic()
        self.mark[ns] = len(self.log(len(self.managers) - 1)) if self.managers else -1
        self.workers[ns] = self._popen(
            [sys.executable, '-m', 'khepera_noise_ros.nodes.worker_pair', '--ros-args',
             '-r', f'__ns:={ns}', '-p', f'steps:={STEPS}', '--log-level', 'error'],
            subprocess.DEVNULL)

    def manager(self, results) -> None:
        log = open(self.tmp / f'manager{len(self.managers)}.log', 'w')
        self.managers.append(self._popen(
            [sys.executable, '-m', 'khepera_noise_ros.nodes.evolution_manager', '--ros-args',
             '-p', f'population:={CONFIG.population}',
             '-p', f'generations:={CONFIG.generations}', '-p', f'trials:={TRIALS}',
             '-p', f'seed:={SEED}', '-p', f'results_path:={results}',
             '-p', "workers:=['/chaos*']", '-p', 'stall_timeout_s:=0.5',
             '-p', 'max_retries:=1000', '-p', 'ready_timeout_s:=60.0'], log))
        log.close()
        self.mark = dict.fromkeys(WORKERS, -1)

    def log(self, i: int) -> str:
        return (self.tmp / f'manager{i}.log').read_text()

    def in_pool(self) -> set[str]:
        """The workers the current manager has taken in (joined, or back) since their last
        start, or that have run for SETTLE_S unmissed."""
        text = self.log(len(self.managers) - 1)
        return {ns for ns in WORKERS if time.monotonic() - self.since[ns] > SETTLE_S
                or any(text.rfind(line) > self.mark[ns]
                       for line in (f'worker {ns} ({ns}/', f'worker {ns} answers again'))}

    def everything(self) -> dict[int, int]:
        found = {p: t for p, t in self.started.items() if t is not None}
        for pid in list(found):
            found.update(descendants(pid))
        return found

    def pause(self, paused: bool) -> None:
        """Stop or continue the running manager (a SIGKILL ends a stopped one as well)."""
        if self.managers[-1].poll() is None:
            self.managers[-1].send_signal(signal.SIGSTOP if paused else signal.SIGCONT)

    def stop(self) -> None:
        self.pause(False)
        for proc in list(self.workers.values()) + self.managers:
            if proc.poll() is None:
                proc.send_signal(signal.SIGINT)
        for proc in list(self.workers.values()) + self.managers:
            try:
                proc.wait(10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()


def read_checkpoint(path) -> dict | None:
    """The checkpoint as it is now; it must always be whole (the test fails otherwise)."""
    try:
        text = path.read_text()
    except FileNotFoundError:
        return None
    state = json.loads(text)                # a half-written file fails here
    assert state['format'] == FORMAT and len(state['batches']) >= 0
    return state


def test_an_evolution_survives_killed_workers_and_a_killed_manager(tmp_path):
    results, checkpoint = tmp_path / 'chaos.json', tmp_path / 'chaos.checkpoint.json'
    rng = random.Random(SEED)
    cast = Cast(tmp_path, next_domain_id())
    kills = {'worker': 0, 'manager': 0, 'pauses': 0}
    reads, began = 0, time.monotonic()
    everything = {}
    due = list(WORKER_KILLS_AT)
    paused = False
    try:
        for ns in WORKERS:
            cast.worker(ns)
        cast.manager(results)
        while cast.managers[-1].poll() is None:
            assert time.monotonic() - began < DEADLINE_S, 'the chaos run did not finish'
            state = read_checkpoint(checkpoint)
            reads += state is not None
            generation = state['generation'] if state else -1
            if not kills['manager'] and generation >= MANAGER_KILL_AT:
                cast.managers[-1].send_signal(signal.SIGKILL)
                cast.managers[-1].wait(10)
                kills['manager'] += 1
                paused = False
                killed_at = read_checkpoint(checkpoint)
                cast.manager(results)                        # resumes from the checkpoint
            elif due and generation >= due[0]:
                # one down at a time: a worker is killed only when every worker is in the pool
                settled = cast.in_pool() == set(WORKERS)
                if settled:
                    if paused:
                        cast.pause(paused := False)
                    ns = rng.choice(WORKERS)
                    cast.workers[ns].send_signal(signal.SIGKILL)
                    cast.workers[ns].wait(10)
                    cast.worker(ns)                          # restarted at once
                    kills['worker'] += 1
                    due.pop(0)
                elif not paused:
                    cast.pause(paused := True)
                    kills['pauses'] += 1
            time.sleep(0.02)
        seconds = time.monotonic() - began
        everything = cast.everything()
        assert cast.managers[-1].returncode == 0, cast.log(len(cast.managers) - 1)[-3000:]
    finally:
        cast.stop()
    record = json.loads(results.read_text())
    for trial, ea in zip(record['trials'], undisturbed()):
        assert trial['best_genome'] == ea.best_genome.tolist()
        assert trial['best_fitness'] == ea.best_fitness
        assert trial['history'] == [vars(g) for g in ea.history]
    assert kills['manager'] == 1, 'the evolution ended before the manager could be killed'
    assert record['resumed']['generation'] == killed_at['generation'] >= MANAGER_KILL_AT
    assert kills['worker'] == len(WORKER_KILLS_AT), kills
    dropped = sum(w['dropped'] is not None or w['failures'] > 0 for w in record['workers'])
    assert not checkpoint.exists() and not list(tmp_path.glob('.*.tmp'))
    left = {}
    for _ in range(200):                    # none of them, nor anything they started
        left = alive(everything)
        if not left:
            break
        time.sleep(0.05)
    assert not left, f'left behind: {left}'
    print(f"\nchaos run: survived {kills['worker']} worker kills and {kills['manager']} "
          f"manager kill (the manager paused {kills['pauses']} times) in {seconds:.1f} s "
          f"({record['episodes']['started']} episodes, {record['episodes']['restarted']} "
          f"restarted; {dropped} worker records with a failure or a drop; checkpoint read "
          f"whole {reads} times)")
