"""The old import path of ``recording.bag``, kept so that existing scripts still import."""
from .recording.bag import read_bag, write_bag  # noqa: F401
