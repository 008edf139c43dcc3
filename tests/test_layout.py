"""The package's shape: subpackages along the data path, imports pointing down it only.

The import graph is read from the source (every ``import`` statement, at
module level or inside functions), so the checks hold whatever
``import uqgear`` happens to load.
"""

from __future__ import annotations

import ast
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

import pytest

import uqgear

PACKAGE = Path(uqgear.__file__).resolve().parent

#: What each layer may import from uqgear (besides itself), lowest first.
ALLOWED: dict[str, set[str]] = {
    "common": set(),
    "physics": {"common"},
    "dynamics": {"common", "physics"},
    "uq": {"common", "physics", "dynamics"},
    "report": {"common", "physics", "dynamics", "uq"},
    "rig": {"common", "physics", "uq"},
    "calibration": {"common", "physics", "uq", "rig", "report"},
    "diagnosis": {"common", "physics", "uq", "rig", "report", "calibration"},
    "validation": {"common", "physics", "uq", "rig", "report", "calibration", "diagnosis"},
    "study": {"common", "physics", "dynamics", "uq", "rig", "report", "calibration", "diagnosis", "validation"},
    "cli": {"common", "physics", "dynamics", "uq", "rig", "report", "calibration", "diagnosis", "validation", "study",
            "package"},
    # uqgear/__init__.py: the public face, and __main__
    "package": {"common", "physics", "dynamics", "uq", "rig", "report", "calibration", "diagnosis", "validation",
                "study", "cli"},
}

#: Third-party modules the physics may not import: plotting and file output.
PHYSICS_FORBIDDEN = ("matplotlib", "netCDF4", "h5netcdf", "tqdm", "dask")

#: Longest module, in lines.
MAX_MODULE_LINES = 800

#: Parts of the package held to the stricter rules below (no private name imported across modules; every
#: public name of a subpackage in its ``__all__``; those of ``SIZED`` also to the sizes). The rest of the
#: package follows as it is brought to them.
STRICT = ("diagnosis", "validation", "common", "cli", "uq", "rig", "report", "study", "dynamics", "calibration")
SIZED = ("common", "physics", "dynamics", "uq", "report", "rig", "calibration", "diagnosis", "validation", "study",
         "cli")
#: Their limits: lines of a module, lines of code of a function (without its docstring, comments and blank
#: lines), lines of a class. A module is cut along its concepts, not to a size: one that holds one concept
#: may run to the package's longest module, while its functions stay short.
STRICT_MODULE_LINES, STRICT_FUNCTION_CODE_LINES, STRICT_CLASS_LINES = 800, 80, 250


def _module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _layer(module: str) -> str:
    parts = module.split(".")
    if len(parts) == 1 or parts[1] in ("__main__",):
        return "package"
    if parts[1] == "cli":
        return "cli"
    return parts[1]


def _imports(path: Path) -> tuple[set[str], set[str]]:
    """(uqgear modules, third-party top-level names) imported anywhere in ``path``."""
    module = _module_name(path)
    is_package = path.name == "__init__.py"
    tree = ast.parse(path.read_text(), filename=str(path))
    internal: set[str] = set()
    external: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                (internal if alias.name.split(".")[0] == "uqgear" else external).add(
                    alias.name if alias.name.startswith("uqgear") else alias.name.split(".")[0])
        elif isinstance(node, ast.ImportFrom):
            if node.level == 0:
                if node.module and node.module.split(".")[0] == "uqgear":
                    internal.add(node.module)
                elif node.module:
                    external.add(node.module.split(".")[0])
                continue
            base = module.split(".") if is_package else module.split(".")[:-1]
            base = base[: len(base) - (node.level - 1)]
            target = ".".join(base + ([node.module] if node.module else []))
            internal.add(target)
            if not node.module:
                # "from . import name": name may be a submodule
                for alias in node.names:
                    candidate = f"{target}.{alias.name}"
                    if (PACKAGE.parent / Path(*candidate.split("."))).with_suffix(".py").exists() or \
                            (PACKAGE.parent / Path(*candidate.split(".")) / "__init__.py").exists():
                        internal.add(candidate)
    return internal, external


def _graph() -> dict[str, set[str]]:
    graph: dict[str, set[str]] = defaultdict(set)
    for path in sorted(PACKAGE.rglob("*.py")):
        module = _module_name(path)
        internal, _ = _imports(path)
        graph[module] |= {name for name in internal if name != module}
    return graph


def test_subpackages_follow_the_data_path():
    expected = set(ALLOWED) - {"package"}
    found = {path.name for path in PACKAGE.iterdir() if (path / "__init__.py").exists()}
    assert found == expected
    for name in expected:
        docstring = ast.get_docstring(ast.parse((PACKAGE / name / "__init__.py").read_text()))
        assert docstring and "import" in docstring, f"uqgear/{name}/__init__.py must say what it may import"


def test_imports_point_down_the_data_path_only():
    upward = []
    for module, targets in _graph().items():
        layer = _layer(module)
        for target in targets:
            other = _layer(target)
            if other != layer and other not in ALLOWED[layer]:
                upward.append(f"{module} imports {target} ({layer} -> {other})")
    assert upward == []


def test_there_is_no_import_circle():
    graph = _graph()
    known = set(graph)

    def resolve(name: str) -> str | None:
        # "uqgear.physics.design" is a module; "uqgear.physics" its package's __init__
        return name if name in known else None

    edges = {module: {t for t in (resolve(x) for x in targets) if t and t != module}
             for module, targets in graph.items()}
    # a package's __init__ importing its own modules is not a circle with them
    edges = {m: {t for t in ts if not (m != "uqgear" and t.startswith(m + ".") and
                                       Path(PACKAGE.parent / Path(*m.split(".")) / "__init__.py").exists())}
             for m, ts in edges.items()}
    edges["uqgear"] = set()  # the public face imports lazily
    white, grey, black = set(edges), set(), set()
    circles = []

    def visit(node: str, path: list[str]) -> None:
        white.discard(node)
        grey.add(node)
        for target in edges.get(node, ()):
            if target in grey:
                circles.append(" -> ".join(path[path.index(target):] + [target]) if target in path
                               else f"{node} -> {target}")
            elif target in white:
                visit(target, path + [target])
        grey.discard(node)
        black.add(node)

    while white:
        start = sorted(white)[0]
        visit(start, [start])
    assert circles == []


def test_physics_never_imports_plotting_or_file_output():
    offenders = []
    for path in sorted((PACKAGE / "physics").rglob("*.py")):
        _, external = _imports(path)
        offenders += [f"{path.name} imports {name}" for name in external if name in PHYSICS_FORBIDDEN]
        if "to_netcdf" in path.read_text():
            offenders.append(f"{path.name} writes netCDF")
    assert offenders == []


def test_importing_the_physics_loads_no_plotting_and_no_higher_layer():
    code = ("import sys, uqgear.physics; "
            "bad = [m for m in sys.modules if m.split('.')[0] in ('matplotlib', 'netCDF4', 'emcee', 'SALib', "
            "'chaospy', 'dask') or (m.startswith('uqgear.') and m.split('.')[1] not in "
            "('common', 'physics'))]; print(bad); sys.exit(1 if bad else 0)")
    completed = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert completed.returncode == 0, completed.stdout + completed.stderr


def test_no_module_is_longer_than_the_limit():
    long = {str(path.relative_to(PACKAGE)): n for path in PACKAGE.rglob("*.py")
            if (n := len(path.read_text().splitlines())) > MAX_MODULE_LINES}
    assert long == {}


@pytest.mark.parametrize("name", ["ParameterSpace", "Interval", "Distribution", "IntervalAnalysis",
                                  "SobolAnalysis", "PolynomialChaos", "response_envelope", "pbox",
                                  "load_design", "simulate", "simulate_batch", "samples_from_mapping",
                                  "mesh_stiffness", "load_study", "run_study", "read_rig", "write_rig",
                                  "calibrate", "Calibration", "diagnose", "UqgearError"])
def test_the_public_face_has_what_the_readme_uses(name):
    assert name in uqgear.__all__
    assert getattr(uqgear, name) is not None


def test_unknown_attributes_are_attribute_errors():
    with pytest.raises(AttributeError, match="no_such_thing"):
        uqgear.no_such_thing  # noqa: B018


def _strict_files(parts: tuple[str, ...] = STRICT) -> list[Path]:
    files = []
    for part in parts:
        path = PACKAGE / part
        files += sorted(path.rglob("*.py")) if path.is_dir() else [path]
    return files


def _code_lines(node: ast.AST, source: list[str]) -> int:
    """Lines of code of a function: its lines less blank ones, comments and its docstring."""
    body = getattr(node, "body", [])
    skip: set[int] = set()
    if body and isinstance(body[0], ast.Expr) and isinstance(getattr(body[0], "value", None), ast.Constant) \
            and isinstance(body[0].value.value, str):
        skip = set(range(body[0].lineno, body[0].end_lineno + 1))
    lines = range(node.lineno, node.end_lineno + 1)
    return sum(1 for number in lines if number not in skip and source[number - 1].strip()
               and not source[number - 1].strip().startswith("#"))


def test_modules_functions_and_classes_keep_their_size():
    """A module holds one concept: at most 800 lines, functions under 80 lines of code, classes under 250 lines."""
    too_long = []
    for path in _strict_files(SIZED):
        text = path.read_text()
        source = text.splitlines()
        name = str(path.relative_to(PACKAGE))
        if len(source) > STRICT_MODULE_LINES:
            too_long.append(f"{name}: {len(source)} lines")
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and \
                    (code := _code_lines(node, source)) > STRICT_FUNCTION_CODE_LINES:
                too_long.append(f"{name}: function {node.name}: {code} lines of code")
            elif isinstance(node, ast.ClassDef) and \
                    (lines := node.end_lineno - node.lineno + 1) > STRICT_CLASS_LINES:
                too_long.append(f"{name}: class {node.name}: {lines} lines")
    assert too_long == []


def _private_imports(path: Path) -> list[str]:
    """Private names (one leading underscore) a module takes from another uqgear module.

    ``from .x import _name`` and ``module._name`` on a uqgear module imported
    under a name (``from ..rig import features as feature_module``).
    """
    module = _module_name(path)
    is_package = path.name == "__init__.py"
    tree = ast.parse(path.read_text(), filename=str(path))
    found, modules = [], set()
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            if node.level == 0 and not (node.module or "").startswith("uqgear"):
                continue
            base = module.split(".") if is_package else module.split(".")[:-1]
            source = node.module if node.level == 0 else ".".join(
                base[: len(base) - (node.level - 1)] + ([node.module] if node.module else []))
            for alias in node.names:
                if alias.name.startswith("_") and not alias.name.startswith("__"):
                    found.append(f"{module} imports {alias.name} from {source}")
                candidate = f"{source}.{alias.name}"
                if (PACKAGE.parent / Path(*candidate.split("."))).with_suffix(".py").exists() or \
                        (PACKAGE.parent / Path(*candidate.split(".")) / "__init__.py").exists():
                    modules.add(alias.asname or alias.name)
        elif isinstance(node, ast.Import):
            modules |= {alias.asname or alias.name for alias in node.names if alias.name.startswith("uqgear")}
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id in modules \
                and node.attr.startswith("_") and not node.attr.startswith("__"):
            found.append(f"{module} reads {node.value.id}.{node.attr}")
    return found


def test_no_private_name_is_imported_across_modules():
    """A name with a leading underscore is its module's own: another module that needs it needs a public name."""
    offenders = [entry for path in _strict_files() for entry in _private_imports(path)]
    assert offenders == []


def _public_names(path: Path) -> tuple[set[str], list[str] | None]:
    """Names a subpackage's ``__init__`` defines or takes from the package (not private), and its ``__all__``."""
    tree = ast.parse(path.read_text(), filename=str(path))
    bound: set[str] = set()
    declared = None
    for node in tree.body:
        if isinstance(node, ast.ImportFrom):
            # what it takes from the package itself (typing's names and the like are not its public parts)
            if node.level > 0 or (node.module or "").startswith("uqgear"):
                bound |= {alias.asname or alias.name for alias in node.names}
        elif isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            bound.add(node.name)
        elif isinstance(node, ast.Assign):
            for target in node.targets:
                if isinstance(target, ast.Name) and target.id == "__all__":
                    try:
                        declared = list(ast.literal_eval(node.value))
                    except ValueError:  # built at import (the package's lazy face): taken as it stands
                        declared = sorted(bound)
                elif isinstance(target, ast.Name):
                    bound.add(target.id)
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            bound.add(node.target.id)
    return {name for name in bound if not name.startswith("_")}, declared


def test_every_subpackage_names_its_public_parts_in_its_all():
    """What a subpackage's ``__init__`` makes public is in its ``__all__``, and its ``__all__`` names only that."""
    missing = []
    for path in _strict_files():
        if path.name != "__init__.py":
            continue
        public, declared = _public_names(path)
        name = str(path.relative_to(PACKAGE))
        if declared is None:
            missing.append(f"{name}: no __all__")
            continue
        submodules = {child.stem for child in path.parent.iterdir()
                      if child.suffix == ".py" or (child / "__init__.py").exists()}
        missing += [f"{name}: {item} not in __all__" for item in sorted(public - set(declared) - submodules)]
        missing += [f"{name}: __all__ names {item}, which it does not define" for item in declared
                    if item not in public]
    assert missing == []
