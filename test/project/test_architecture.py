"""The package's structure: its own imports form no circle and never climb a layer, and no
module is longer than 500 lines (docs/architecture.md explains the layers)."""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = 'khepera_noise_ros'
ROOT = Path(__file__).resolve().parents[2] / PACKAGE
MAX_LINES = 500

# Lower layers never import higher ones; a module may import its own layer or below.
LAYERS = (
    ('files', 'lifeline', 'memo', 'core'),                  # plain utilities and the paper's model
    ('effects', 'simconfig', 'recording', 'bag', 'convert', 'reality'),   # effects, data, worlds
    ('gap', 'synchrony'),                                   # analyses of recordings
    ('nodes', 'experiment'),                         # ROS adapters, the experiments
    ('commands',),                                   # one module per subcommand
    ('cli', 'tools', 'testing'),                     # entry points; the tests' helpers
)
# Beyond the layers: who may not use whom at all (a package, the packages it must not import).
APART = (
    ('nodes', ('gap',)),              # the simulator runs fitted effects without the diagnosis
    ('effects', ('gap', 'recording', 'reality')),    # the effects know nothing of what fits them
    ('reality', ('effects', 'gap', 'simconfig')),    # the emulator shares no code with the fit
)


def layer_of(module: str) -> int:
    """The layer of a package module, from its first name below the package."""
    parts = module.split('.')
    top = parts[1] if len(parts) > 1 else ''
    if top in ('', '__init__'):
        return -1                                    # the package itself: the version only
    for rank, names in enumerate(LAYERS):
        if top in names:
            return rank
    raise AssertionError(f'{module} is in no layer: give {top!r} one in LAYERS (and in '
                         'docs/architecture.md)')


def module_name(path: Path, root: Path) -> str:
    parts = list(path.relative_to(root.parent).with_suffix('').parts)
    if parts[-1] == '__init__':
        parts.pop()
    return '.'.join(parts)


def imports(path: Path, root: Path, modules: set[str]) -> set[str]:
    """The package modules ``path`` imports, at any depth in the file (inside functions
    too): ``from . import x`` names module x when x is one, else the package."""
    name = module_name(path, root)
    package = name if path.name == '__init__.py' else name.rpartition('.')[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            targets = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split('.')
                base = base[:len(base) - node.level + 1]
                source = '.'.join(base + ([node.module] if node.module else []))
            else:
                source = node.module or ''
            targets = [f'{source}.{a.name}' if f'{source}.{a.name}' in modules else source
                       for a in node.names]
        else:
            continue
        for target in targets:
            while target and target not in modules:      # a name inside a module
                target = target.rpartition('.')[0]
            if target and target != name:
                found.add(target)
    return found


def import_graph(root: Path = ROOT) -> dict[str, set[str]]:
    """Each module of the package (by dotted name) and the package modules it imports."""
    files = sorted(root.rglob('*.py'))
    modules = {module_name(f, root) for f in files}
    return {module_name(f, root): imports(f, root, modules) for f in files}


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """One circle through each strongly connected group of modules (Tarjan's algorithm)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    groups: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = []
            while True:
                w = stack.pop()
                group.append(w)
                if w == v:
                    break
            if len(group) > 1:
                groups.append(sorted(group))
    for v in sorted(graph):
        if v not in index:
            visit(v)
    return groups


def upward(graph: dict[str, set[str]]) -> list[str]:
    """'a -> b' for every import of a module in a higher layer than the importer's."""
    return [f'{a} (layer {layer_of(a)}) -> {b} (layer {layer_of(b)})'
            for a, targets in sorted(graph.items()) for b in sorted(targets)
            if layer_of(b) > layer_of(a)]


def crossings(graph: dict[str, set[str]]) -> list[str]:
    """'a -> b' for every import ``APART`` forbids."""
    def top(module: str) -> str:
        return module.split('.')[1] if '.' in module else ''
    banned = dict(APART)
    return [f'{a} -> {b}' for a, targets in sorted(graph.items()) for b in sorted(targets)
            if top(b) in banned.get(top(a), ())]


def long_modules(root: Path = ROOT, limit: int = MAX_LINES) -> list[str]:
    return [f'{p.relative_to(root.parent)}: {n} lines' for p in sorted(root.rglob('*.py'))
            if (n := len(p.read_text().splitlines())) > limit]


# --- the package ---------------------------------------------------------------------------

def test_the_package_imports_form_no_circle():
    assert circles(import_graph()) == []


def test_no_module_imports_a_higher_layer():
    assert upward(import_graph()) == []


def test_no_package_imports_one_it_must_stay_apart_from():
    assert crossings(import_graph()) == []


def test_no_module_is_longer_than_500_lines():
    assert long_modules() == []


def test_every_subpackage_has_a_layer():
    for module in import_graph():
        layer_of(module)


# --- the checks themselves can fail ------------------------------------------------------

def _write(root: Path, files: dict[str, str]) -> Path:
    pkg = root / PACKAGE
    for name, text in files.items():
        path = pkg / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)
    return pkg


def test_a_circle_through_a_lazy_import_is_found(tmp_path):
    pkg = _write(tmp_path, {
        '__init__.py': '',
        'nodes/__init__.py': 'def f():\n    from .graph import g\n',     # inside a function
        'nodes/graph.py': 'from . import workers\n',
        'nodes/workers.py': 'from . import f\n',                          # a name, not a module
    })
    graph = import_graph(pkg)
    assert graph[f'{PACKAGE}.nodes.workers'] == {f'{PACKAGE}.nodes'}
    assert circles(graph) == [[f'{PACKAGE}.nodes', f'{PACKAGE}.nodes.graph',
                               f'{PACKAGE}.nodes.workers']]


def test_an_upward_import_is_found(tmp_path):
    pkg = _write(tmp_path, {
        '__init__.py': '',
        'core/__init__.py': '',
        'core/task.py': 'import numpy\n\ndef run():\n    from ..nodes.graph import Thing\n',
        'nodes/__init__.py': '',
        'nodes/graph.py': 'from ..core.task import run\n',
    })
    graph = import_graph(pkg)
    assert circles(graph) == [[f'{PACKAGE}.core.task', f'{PACKAGE}.nodes.graph']]
    assert upward(graph) == [f'{PACKAGE}.core.task (layer 0) -> {PACKAGE}.nodes.graph (layer 3)']


def test_absolute_imports_count_and_outside_ones_do_not(tmp_path):
    pkg = _write(tmp_path, {
        '__init__.py': '',
        'recording/__init__.py': f'import os\nimport {PACKAGE}.cli\n',
        'cli.py': 'import numpy as np\n',
    })
    assert import_graph(pkg)[f'{PACKAGE}.recording'] == {f'{PACKAGE}.cli'}
    assert upward(import_graph(pkg)) == [
        f'{PACKAGE}.recording (layer 1) -> {PACKAGE}.cli (layer 5)']


def test_a_module_without_a_layer_is_named(tmp_path):
    pkg = _write(tmp_path, {'__init__.py': '', 'misc.py': ''})
    with pytest.raises(AssertionError, match="'misc'"):
        [layer_of(m) for m in import_graph(pkg)]


def test_a_long_module_is_found(tmp_path):
    pkg = _write(tmp_path, {'__init__.py': '', 'core/long.py': 'x = 1\n' * 501,
                            'core/short.py': 'x = 1\n' * 500})
    assert long_modules(pkg) == [f'{PACKAGE}/core/long.py: 501 lines']
