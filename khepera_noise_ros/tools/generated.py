"""A docs page generated from code: written, or with ``--check`` compared (exit 1 when stale)."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Callable


def main(render: Callable[[], str], page: Path, module: str, source: str,
         description: str, argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument('--check', action='store_true',
                        help=f'exit 1 if the page differs from what {source}')
    parser.add_argument('--output', type=Path, default=page)
    args = parser.parse_args(argv)
    text = render()
    if args.check:
        if not args.output.exists() or args.output.read_text() != text:
            print(f'{args.output} is out of date: run python -m {module}', file=sys.stderr)
            return 1
        return 0
    args.output.write_text(text)
    return 0
