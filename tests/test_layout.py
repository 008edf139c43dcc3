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
    "study": {"common", "physics", "dynamics", "uq", "rig", "report", "calibration", "diagnosis"},
    "cli": {"common", "physics", "dynamics", "uq", "rig", "report", "calibration", "diagnosis", "study",
            "package"},
    # uqgear/__init__.py: the public face, and __main__
    "package": {"common", "physics", "dynamics", "uq", "rig", "report", "calibration", "diagnosis", "study",
                "cli"},
}

#: Third-party modules the physics may not import: plotting and file output.
PHYSICS_FORBIDDEN = ("matplotlib", "netCDF4", "h5netcdf", "tqdm", "dask")

#: Longest module, in lines.
MAX_MODULE_LINES = 800


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
    expected = set(ALLOWED) - {"cli", "package"}
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
