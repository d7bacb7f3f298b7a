"""
The package's layout rules (docs/DEVELOPING.md), checked on the source tree.

- Features never import each other: a module of a feature imports only the ground floor
  (``errors``, ``fileio``, ``frames``, ``paramspec``, ``sensor/``, ``camera/``,
  ``recording/``, ``rosutil/``) and its own feature. Only the ``accelcal`` dispatcher
  (``cli.py``) sees every feature.
- The ground floor imports no feature.
- No module is longer than 600 lines.
- At least 80 % of the public functions and methods of the core (everything but node
  modules) carry type hints.
"""
import ast
import os

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PACKAGE = os.path.join(REPO, 'accelcal_ros')
FEATURES = ('driver', 'calibration', 'attitude', 'panorama', 'p2p', 'lidar', 'rig')
MAX_LINES = 600
MIN_TYPED_FRACTION = 0.8


def _modules():
    for dirpath, _, files in os.walk(PACKAGE):
        for name in sorted(files):
            if name.endswith('.py'):
                path = os.path.join(dirpath, name)
                yield os.path.relpath(path, PACKAGE), path


def _top(rel):
    parts = rel.split(os.sep)
    return parts[0] if len(parts) > 1 else parts[0][:-3]


def _imported_subpackages(tree):
    for item in ast.walk(tree):
        names = []
        if isinstance(item, ast.Import):
            names = [a.name for a in item.names]
        elif isinstance(item, ast.ImportFrom) and item.module and item.level == 0:
            names = [item.module]
        for mod in names:
            parts = mod.split('.')
            if parts[0] == 'accelcal_ros' and len(parts) > 1:
                yield item.lineno, parts[1]


def test_features_import_only_the_ground_floor_and_themselves():
    """No feature imports another; the ground floor imports no feature."""
    offenders = []
    for rel, path in _modules():
        top = _top(rel)
        if top in ('cli', '__main__', 'demo', 'sample_data'):
            continue
        with open(path, encoding='utf-8') as handle:
            tree = ast.parse(handle.read(), path)
        for line, target in _imported_subpackages(tree):
            if target in FEATURES and target != top:
                offenders.append(f'{rel}:{line}: {top} imports feature {target}')
    assert not offenders, '\n'.join(offenders)


def test_no_module_is_longer_than_the_limit():
    """Every module holds one job: at most 600 lines."""
    long_ones = []
    for rel, path in _modules():
        with open(path, encoding='utf-8') as handle:
            count = sum(1 for _ in handle)
        if count > MAX_LINES:
            long_ones.append(f'{rel}: {count} lines')
    assert not long_ones, '\n'.join(long_ones)


def _is_node_module(rel):
    base = os.path.basename(rel)
    return (base == 'node.py' or base.endswith(('_node.py', '_ros.py'))
            or rel.startswith('rosutil' + os.sep) or rel.startswith('demo' + os.sep))


def _public_functions(tree):
    """Yield public module-level functions and public methods of public classes."""
    for item in tree.body:
        if isinstance(item, (ast.FunctionDef, ast.AsyncFunctionDef)):
            if not item.name.startswith('_'):
                yield item
        elif isinstance(item, ast.ClassDef) and not item.name.startswith('_'):
            for sub in item.body:
                if (isinstance(sub, (ast.FunctionDef, ast.AsyncFunctionDef))
                        and (not sub.name.startswith('_') or sub.name == '__init__')):
                    yield sub


def _is_typed(func):
    args = func.args
    every = args.posonlyargs + args.args + args.kwonlyargs
    params = [a for a in every if a.arg not in ('self', 'cls')]
    if args.vararg is not None:
        params.append(args.vararg)
    if args.kwarg is not None:
        params.append(args.kwarg)
    params_typed = all(a.annotation is not None for a in params)
    return params_typed and (func.returns is not None or func.name == '__init__')


def typed_fraction():
    """Return ``(typed, total, untyped names)`` over the core's public functions."""
    typed = total = 0
    untyped = []
    for rel, path in _modules():
        if _is_node_module(rel):
            continue
        with open(path, encoding='utf-8') as handle:
            tree = ast.parse(handle.read(), path)
        for func in _public_functions(tree):
            total += 1
            if _is_typed(func):
                typed += 1
            else:
                untyped.append(f'{rel}:{func.lineno} {func.name}')
    return typed, total, untyped


def test_the_core_is_typed():
    """At least 80 % of the core's public functions have full type hints."""
    typed, total, untyped = typed_fraction()
    fraction = typed / max(total, 1)
    assert fraction >= MIN_TYPED_FRACTION, (
        f'{typed}/{total} = {fraction:.0%} typed; untyped:\n' + '\n'.join(untyped))


def test_the_package_says_it_is_typed():
    """``py.typed`` (PEP 561) ships with the package."""
    assert os.path.exists(os.path.join(PACKAGE, 'py.typed'))
