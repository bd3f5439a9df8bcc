"""The ROS domains the tests use (khepera_noise_ros.testing.domains): the pytest-xdist
workers of a run never share one, all are ids Fast DDS accepts, and this very run set them
up before rclpy loaded."""
import os

import pytest

from khepera_noise_ros.testing import domains


@pytest.mark.parametrize('count', [1, 2, 3, 7, 116])
@pytest.mark.parametrize('base', [0, 42, 171, 231, 4095])
def test_the_workers_of_a_run_hold_disjoint_blocks_of_valid_ids(base, count):
    size = domains.IDS // count
    blocks = [{domains.domain(base, w, count, n) for n in range(3 * size)}
              for w in range(count)]
    assert all(len(b) == size for b in blocks)        # n wraps within the worker's block
    assert len(set().union(*blocks)) == size * count  # no id in two blocks
    assert set().union(*blocks) <= set(range(1, 233))


def test_a_worker_hands_out_its_block_but_never_its_home(monkeypatch):
    monkeypatch.setenv(domains.BASE, '171')
    monkeypatch.setenv('PYTEST_XDIST_WORKER', 'gw1')
    monkeypatch.setenv('PYTEST_XDIST_WORKER_COUNT', '2')
    home = domains.domain(171, 1, 2, 0)
    handed = {domains.next_domain_id() for _ in range(2 * 116)}
    assert home not in handed and len(handed) == 115
    assert handed.isdisjoint(domains.domain(171, 0, 2, n) for n in range(116))


def test_claim_keeps_the_run_s_base_and_sets_the_worker_s_home(monkeypatch):
    monkeypatch.delenv(domains.BASE)
    monkeypatch.setenv('ROS_DOMAIN_ID', '42')
    monkeypatch.setenv('PYTEST_XDIST_WORKER', 'gw2')
    monkeypatch.setenv('PYTEST_XDIST_WORKER_COUNT', '4')
    home = domains.claim()
    assert home == domains.domain(42, 2, 4, 0) == int(os.environ['ROS_DOMAIN_ID'])
    assert domains.claim() == home and os.environ[domains.BASE] == '42'


def test_too_many_workers_are_refused_by_name(monkeypatch):
    monkeypatch.setenv('PYTEST_XDIST_WORKER', 'gw0')
    monkeypatch.setenv('PYTEST_XDIST_WORKER_COUNT', '117')
    with pytest.raises(ValueError, match="worker 'gw0' of 117: at most 116"):
        domains.worker()


def test_this_run_claimed_its_domain_before_rclpy_loaded():
    assert os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'LOCALHOST'
    index, count = domains.worker()
    assert int(os.environ['ROS_DOMAIN_ID']) == domains.domain(
        int(os.environ[domains.BASE]), index, count, 0)
