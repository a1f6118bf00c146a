"""The layers, as a matrix of allowed imports between the project's packages.

    humancal     the pure library: only itself (and third-party packages other than dagster)
    evaluation   metrics and protocols: humancal
    resources    Dagster resources and IO managers: humancal, dagster
    assets       thin Dagster assets: humancal, evaluation, resources, dagster
    pipelines    definitions, CLI, update engine: everything
    scripts      developer scripts: humancal, evaluation
    tests        everything

Every import statement counts, also those inside functions. For the pure packages the test also imports
every module and checks what got loaded, which catches an import hidden behind another module.
"""

import ast
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
PACKAGES = ("humancal", "evaluation", "resources", "assets", "pipelines", "scripts", "tests")
EVERYTHING = frozenset(PACKAGES) | {"dagster"}
ALLOWED = {
    "humancal": frozenset(),
    "evaluation": frozenset({"humancal"}),
    "resources": frozenset({"humancal", "dagster"}),
    "assets": frozenset({"humancal", "evaluation", "resources", "dagster"}),
    "pipelines": EVERYTHING,
    "scripts": frozenset({"humancal", "evaluation"}),
    "tests": EVERYTHING,
}
"""What each package may import besides itself and third-party packages."""
EXCEPTIONS = {
    "scripts/bench_calibration.py": frozenset({"assets", "pipelines", "resources"}),
    "scripts/bench_graph.py": frozenset({"assets", "pipelines", "dagster"}),
    "scripts/overlay_alignment.py": frozenset({"pipelines"}),
}
"""Modules allowed more than their package. ``bench_calibration`` times the pipeline's stages on the artifacts the
pipeline stored, with the pipeline's settings: it reads them where they are defined rather than copying them.
``bench_graph`` materializes the pipeline's own definitions in a fresh state dir and times them from Dagster's run
history, as the ``stage_timings`` asset does. ``overlay_alignment`` measures what ``humancal export overlays`` draws,
on a partition's stored result read as that command reads it."""
FORBIDDEN_EDGES = [(src, dst) for src in PACKAGES for dst in sorted(EVERYTHING - ALLOWED[src] - {src})]
PURE = ("humancal", "evaluation")


def _imports(path: Path) -> list[tuple[int, str]]:
    """(line, top-level name) of every absolute import in a module."""
    out = []
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        if isinstance(node, ast.Import):
            out += [(node.lineno, alias.name.split(".")[0]) for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            out.append((node.lineno, node.module.split(".")[0]))
    return out


def _modules(package: str) -> list[Path]:
    return sorted(p for p in (REPO / package).rglob("*.py") if ".venv" not in p.parts)


def test_every_package_is_in_the_matrix():
    top_level = {p.name for p in REPO.iterdir() if p.is_dir() and any(p.glob("*.py"))}
    assert top_level <= set(PACKAGES), f"packages without a row in the layering matrix: {sorted(top_level - set(PACKAGES))}"


@pytest.mark.parametrize(("src", "dst"), FORBIDDEN_EDGES, ids=[f"{s}-imports-{d}" for s, d in FORBIDDEN_EDGES])
def test_forbidden_edge(src, dst):
    offenders = [
        f"{path.relative_to(REPO)}:{line}"
        for path in _modules(src)
        for line, name in _imports(path)
        if name == dst and dst not in EXCEPTIONS.get(path.relative_to(REPO).as_posix(), ())
    ]
    assert not offenders, f"{src} must not import {dst} (allowed: {sorted(ALLOWED[src]) or 'itself only'}): {offenders}"


@pytest.mark.parametrize("package", PURE)
def test_importing_a_pure_package_loads_no_forbidden_package(package):
    modules = [".".join(p.relative_to(REPO).with_suffix("").parts).removesuffix(".__init__") for p in _modules(package)]
    forbidden = sorted(EVERYTHING - ALLOWED[package] - {package})
    code = (
        "import importlib, sys\n"
        f"for m in {modules!r}:\n"
        "    importlib.import_module(m)\n"
        f"bad = sorted({{m.split('.')[0] for m in sys.modules}} & set({forbidden!r}))\n"
        "print(','.join(bad))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    loaded = out.stdout.strip().splitlines()[-1] if out.stdout.strip() else ""
    assert loaded == "", f"importing {package} loaded {loaded}"


def _module_graph(packages: tuple[str, ...]) -> dict[str, set[str]]:
    """module -> the project modules it imports (every import statement, inside functions and ``TYPE_CHECKING``
    blocks too; ``from package import name`` counts as importing ``package.name`` when that is a module). A module
    importing one of its own packages is left out: a package's ``__init__`` gathering its modules is no circle."""
    paths = {".".join(p.relative_to(REPO).with_suffix("").parts).removesuffix(".__init__"): p
             for package in packages for p in _modules(package)}
    graph: dict[str, set[str]] = {name: set() for name in paths}
    for name, path in paths.items():
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            targets = []
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                targets = [f"{node.module}.{alias.name}" for alias in node.names] + [node.module]
            for target in targets:
                while target and target not in paths:
                    target = target.rpartition(".")[0]
                if target and target != name and not name.startswith(f"{target}."):
                    graph[name].add(target)
    return graph


def test_no_import_circle():
    """No two modules import each other, directly or through others (issue: `tracking` <-> `tracks`, `cli` <->
    `capture_cli`)."""
    import graphlib

    graph = _module_graph(("humancal", "evaluation", "resources", "assets", "pipelines"))
    try:
        graphlib.TopologicalSorter(graph).prepare()
    except graphlib.CycleError as error:
        pytest.fail(f"import circle: {' -> '.join(error.args[1])}")
    # the check sees a circle when there is one
    graph["humancal.camera"].add("humancal.geometry.triangulation")
    with pytest.raises(graphlib.CycleError):
        graphlib.TopologicalSorter(graph).prepare()
