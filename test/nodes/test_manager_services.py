"""The evolution manager's conventions: best_fitness reaches a late subscriber, the stop
service ends a run cleanly after its checkpoint, and health goes on /diagnostics."""
import json

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.node import Node
from std_msgs.msg import Float64
from std_srvs.srv import Trigger

from khepera_noise_ros.nodes.evolution_manager import BEST_FITNESS_QOS
from khepera_noise_ros.nodes.local_graph import local_graph
from khepera_noise_ros.testing.evolutions import CONFIG, SEED, STEPS, TRIALS, \
    assert_same_evolution, core_run
from khepera_noise_ros.testing.probe import TIMEOUT, wait_for


class User(Node):
    """What a user's tool does: calls ~/stop, listens to best_fitness and /diagnostics."""

    def __init__(self, context):
        super().__init__('user', context=context)
        self.best: list[float] = []
        self.diagnostics: list[DiagnosticArray] = []
        self.stop = self.create_client(Trigger, '/evolution_manager/stop')
        self.create_subscription(DiagnosticArray, '/diagnostics', self.diagnostics.append, 10)

    def listen_to_best(self) -> None:
        self.create_subscription(Float64, 'best_fitness', lambda m: self.best.append(m.data),
                                 BEST_FITNESS_QOS)

    def call_stop(self) -> Trigger.Response:
        assert self.stop.wait_for_service(TIMEOUT)
        future = self.stop.call_async(Trigger.Request())
        assert wait_for(future.done)
        return future.result()


def test_stop_ends_a_run_after_its_checkpoint_and_a_restart_resumes_it(
        ros_context, tmp_path):
    eas, _ = core_run()
    results = tmp_path / 'run.json'
    checkpoint = tmp_path / 'run.checkpoint.json'
    manager = {'population': CONFIG.population, 'generations': CONFIG.generations,
               'trials': TRIALS, 'seed': SEED, 'results_path': str(results)}
    with local_graph(ros_context, simulator={'steps': STEPS}, manager=manager,
                     trace=False) as graph:
        user = User(ros_context)
        graph.executor.add_node(user)
        mgr = graph.manager
        assert not user.call_stop().success                     # nothing runs yet
        finished = mgr.start()
        assert wait_for(lambda: mgr._published >= 1 or finished.done(), 60)
        answer = user.call_stop()
        assert answer.success and str(checkpoint) in answer.message
        assert wait_for(finished.done, 60)
        stopped = finished.result()
        assert stopped['stopped'] and stopped['checkpoint'] == str(checkpoint)
        assert stopped['generation'] < CONFIG.generations
        state = json.loads(checkpoint.read_text())
        assert state['generation'] == stopped['generation']
        assert not results.exists()

        user.listen_to_best()                   # late: still gets the latest generation's
        assert wait_for(lambda: len(user.best) == 1)
        history = state['history']
        assert user.best[0] == max(h[stopped['generation']]['best'] for h in history)

        record = mgr.start()
        assert wait_for(record.done, 120)
        record = record.result()
        assert record['resumed']['generation'] == stopped['generation']
        assert_same_evolution(record, eas)
        assert json.loads(results.read_text()) == record

        def health() -> list[DiagnosticStatus]:
            return [s for a in list(user.diagnostics) for s in a.status]
        assert wait_for(lambda: any('worker' in s.name for s in health())
                        and any(s.name == '/simulator: messages' for s in health()))
        worker = [s for s in health() if 'worker' in s.name][-1]
        assert worker.level == DiagnosticStatus.OK and worker.message == 'in the pool'
        assert int({kv.key: kv.value for kv in worker.values}['episodes']) > 0
    user.destroy_node()         # once the graph's executor has stopped spinning it
