"""How large the diagnosis is (prints figures; not a test).

    python benchmark/size.py [PACKAGE_DIR ...]

Lines of each module of ``khepera_noise_ros/gap`` and ``khepera_noise_ros/effects``
(default), as ``wc -l`` counts them, split into code, docstrings, comments and blank
lines (the docstrings found by ``ast``), and the total of all of them.
"""
from __future__ import annotations

import argparse
import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent / 'khepera_noise_ros'
DEFAULT = (ROOT / 'gap', ROOT / 'effects')
DOCUMENTED = (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)


def counts(path: Path) -> tuple[int, int, int, int, int]:
    """(lines, code, docstring, comment, blank) of one source file."""
    text = path.read_text()
    lines = text.splitlines()
    doc: set[int] = set()
    for node in ast.walk(ast.parse(text)):
        first = node.body[0] if isinstance(node, DOCUMENTED) and node.body else None
        if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant) \
                and isinstance(first.value.value, str):
            doc.update(range(first.lineno, (first.end_lineno or first.lineno) + 1))
    blank = sum(1 for line in lines if not line.strip())
    comment = sum(1 for i, line in enumerate(lines, 1)
                  if line.strip().startswith('#') and i not in doc)
    return len(lines), len(lines) - len(doc) - comment - blank, len(doc), comment, blank


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    p.add_argument('dirs', nargs='*', type=Path, default=list(DEFAULT))
    args = p.parse_args(argv)
    print(f'{"module":44s} {"lines":>6s} {"code":>6s} {"doc":>6s} {"comment":>7s} {"blank":>6s}')
    total = [0] * 5
    for d in args.dirs:
        for path in sorted(d.glob('*.py')):
            row = counts(path)
            total = [a + b for a, b in zip(total, row)]
            print(f'{path.parent.name + "/" + path.name:44s} {row[0]:6d} {row[1]:6d} '
                  f'{row[2]:6d} {row[3]:7d} {row[4]:6d}')
    print(f'{"total":44s} {total[0]:6d} {total[1]:6d} {total[2]:6d} {total[3]:7d} {total[4]:6d}')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
