"""What the gap tests share: a RuntimeWarning (a division by zero, a mean of nothing) fails
the test; the blind benchmark's emulated robot recorded with no effects; and the rounding
the value lattice prefers."""
from pathlib import Path

import pytest

from khepera_noise_ros.gap import diagnose
from khepera_noise_ros.gap.compare import paired_p
from khepera_noise_ros.gap.families import having
from khepera_noise_ros.gap.target import Target
from khepera_noise_ros.reality import effects as emu
from khepera_noise_ros.testing import emulated

HERE = Path(__file__).resolve().parent


def pytest_collection_modifyitems(items):
    for item in items:
        if HERE in Path(item.path).resolve().parents:
            item.add_marker(pytest.mark.filterwarnings('error::RuntimeWarning'))


@pytest.fixture(scope='session')
def clean_robot():
    """The blind benchmark's emulated robot with no effects, its stationary protocol (5
    conditions x 2 repeats).  Tests change a copy."""
    return emulated.record_stationary(emulated.robot(emu.EffectsConfig.none(0.02), 3))


def _lattice(t: Target, c) -> tuple:
    """(the value-lattice statistics' discrepancy in ``c``, the same per real replicate)."""
    part = c.select([k.family in having('lattice') for k in c.keys])
    return part.discrepancy, t.replicate_discrepancies(part)


def _lattice_choice(t: Target, given) -> dict:
    """The rounding the value lattice prefers with ``given`` in the simulator, by the rule
    the diagnosis applies on its fitting part: the other rounding only if it lowers the
    lattice statistics' discrepancy by ``LATTICE_SHARE`` in 95% of the paired replicates."""
    here = t.config.noise.rounding
    other = 'reading' if here == 'level' else 'level'
    d0, reps0 = _lattice(t, t.compare(given, replicates=diagnose.LATTICE_REPLICATES))
    alt = t.with_config(diagnose.with_rounding(t.config, other))
    d1, reps1 = _lattice(alt, alt.compare(given, replicates=diagnose.LATTICE_REPLICATES))
    p = paired_p(reps0, reps1, d0, d1)
    better = d0 > 0 and d1 <= (1 - diagnose.LATTICE_SHARE) * d0 and \
        p < diagnose.REDUCTION_ALPHA
    return {'rounding': other if better else here, 'given': here,
            'lattice': {here: d0, other: d1}, 'p_value': p}


@pytest.fixture
def lattice_choice():
    """``_lattice_choice``: {rounding, given, lattice, p_value} of a target and effects."""
    return _lattice_choice
