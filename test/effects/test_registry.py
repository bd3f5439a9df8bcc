"""The registry's dict and JSON forms (``effects.from_dict``, ``dumps``, ``loads``): bad
input is refused in one line naming what is wrong; the turn error's creep is a
parameter of its own that older effects do without; a world part's plain case is nested
in it."""
import numpy as np
import pytest

from khepera_noise_ros import effects as fx
from khepera_noise_ros.effects import (NAMES, REGISTRY, WORLD_MODEL, ActuatorResponse,
                                       ActuatorTurnError)


def test_a_bad_effect_is_refused_naming_the_field_or_the_name():
    with pytest.raises(ValueError, match="name from .*'wobble'"):
        fx.from_dict({'name': 'wobble'})
    with pytest.raises(ValueError, match=r"unknown field\(s\) \['delay'\]"):
        fx.from_dict({'name': 'sensor_latency', 'delay': 2})
    with pytest.raises(ValueError, match='JSON list of effects'):
        fx.loads('[{"name": ')
    with pytest.raises(ValueError, match='JSON list, got dict'):
        fx.loads('{"name": "sensor_latency"}')
    assert fx.loads('') == () and fx.dumps([]) == ''


def test_a_creep_at_power_0_is_its_own_parameter():
    """A creep turns the robot when no turn is commanded; its draws come after the
    slip's, so effects without it replay as before."""
    rng = np.random.default_rng(0)
    turn = ActuatorTurnError(1.0, 0.0, creep=2.0).start(1, 8, rng)
    still = np.array([turn(np.zeros(1))[0] for _ in range(2000)])
    assert np.std(still) == pytest.approx(2.0, rel=0.1)
    plain = ActuatorTurnError(1.0, 0.2).start(1, 8, np.random.default_rng(1))
    old = ActuatorTurnError(1.0, 0.2, creep=0.0).start(1, 8, np.random.default_rng(1))
    assert plain(np.array([10.0]))[0] == old(np.array([10.0]))[0]
    back = fx.from_dict(ActuatorTurnError(0.9, 0.1, creep=1.5).to_dict())
    assert back.creep == 1.5
    assert fx.from_dict({'name': 'actuator_turn_error', 'scale': 0.9, 'slip': 0.1}).creep == 0
    with pytest.raises(ValueError, match='creep must be a finite number >= 0'):
        fx.from_dict({'name': 'actuator_turn_error', 'creep': -1.0})


def test_a_plain_case_is_an_unmodelled_effect_nested_in_its_world_part():
    plain = {n: REGISTRY[n].plain for n in WORLD_MODEL if REGISTRY[n].plain}
    assert plain == {'actuator_response': 'actuator_turn_error'}
    assert all(REGISTRY[n].plain is None for n in NAMES)
    for part, case in plain.items():
        assert REGISTRY[case].stage is REGISTRY[part].stage
        assert REGISTRY[case].free < REGISTRY[part].free
    commanded = np.array([-21.0, -3.0, 0.0, 3.0, 9.0, 27.0])
    rng = np.random.default_rng(0)
    made = ActuatorTurnError(0.6).act(commanded.reshape(1, 1, -1), rng).ravel()
    np.testing.assert_allclose(ActuatorResponse(gain=0.6).mean(commanded), made)
