"""The effects tests: a RuntimeWarning (a division by zero, a mean of nothing) fails the test."""
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent


def pytest_collection_modifyitems(items):
    for item in items:
        if HERE in Path(item.path).resolve().parents:
            item.add_marker(pytest.mark.filterwarnings('error::RuntimeWarning'))
