"""docs/diagnosis.md's "Adding an effect" holds: its example effect, written as the page
shows and registered, passes every check of the contract and is fitted and scored by the
diagnosis with the others."""
from __future__ import annotations

import re
import sys
import types
from pathlib import Path

import pytest

from khepera_noise_ros import effects as fx
from khepera_noise_ros.testing.contract import (FitCase, check_fit, check_paths,
                                                check_round_trip, check_validation)

PAGE = Path(__file__).resolve().parents[2] / 'docs' / 'diagnosis.md'


@pytest.fixture
def sensor_bias(monkeypatch):
    """The page's effect, as the module it shows, registered as the page says."""
    text = PAGE.read_text()
    code = re.search(r'## Adding an effect.*?```python\n(.*?)```', text, re.S)
    assert code, 'the walk-through lost its example'
    module = types.ModuleType('sensor_bias')
    monkeypatch.setitem(sys.modules, 'sensor_bias', module)
    exec(compile(code.group(1), str(PAGE), 'exec'), module.__dict__)
    cls = module.SensorBias
    monkeypatch.setitem(fx.REGISTRY, cls.name, cls)
    return cls


def test_the_walkthroughs_effect_keeps_the_contract(sensor_bias, tmp_path):
    example = sensor_bias((1, 4), (12.0, -8.0))
    check_validation(sensor_bias, example)
    check_round_trip(sensor_bias, example, tmp_path)
    check_paths(sensor_bias, example)
    check_fit(sensor_bias, FitCase(sensor_bias((1, 4), (15.0, -10.0)), False,
                                   {'bias': ((15.0, -10.0), 4.0)}))
