"""Foreign Kheperas: draw them, serve them on pseudo-terminals, measure their learnability.

    python benchmark/foreign_robots.py draw [--seed 26] [--count 10] [--first 0]
    python benchmark/foreign_robots.py serve ROBOT [--robots N] [--link PREFIX]
    python benchmark/foreign_robots.py learnability [ROBOT ...] [--trials 10]
        [--test-episodes 10] [--seed 26] [--out benchmark/foreign/learnability.json]
    python benchmark/foreign_robots.py list [--learnable]

The commands live in benchmark/foreign/cli.py (docs/foreign-robots.md).
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

from foreign.cli import *  # noqa: E402,F401,F403
from foreign.cli import main  # noqa: E402

if __name__ == '__main__':
    sys.exit(main())
