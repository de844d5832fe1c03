"""The layout the code keeps: no import cycles between modules nor between packages, the method free of presentation,
no private name used across modules, commands that start without the heavy libraries, and a daemon whose supervisor
loads neither MuJoCo nor matplotlib.

The imports are read from the source files with :mod:`ast` (every import, at
the top of a module or inside a function, except those under
``if TYPE_CHECKING:``), so a cycle hidden in a function is found too.
"""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
PACKAGES = ("fcso", "fcsod")

#: Presentation: writing folders, pages and pictures. The method must not import it.
PRESENTATION = ("fcso.output", "fcso.cli", "fcso.verify_cli", "matplotlib")
#: What the method may take from the output package: the names of the folder layout, which the reports record.
LAYOUT = "fcso.layout"
#: Libraries that take long to import and serve only some commands: a command's start-up loads none of them
#: unless it uses them (numba: the compiled kernels of the pipeline; MuJoCo: the verification; matplotlib: the
#: pictures; HiGHS: the holding forces; Dask: a cluster).
HEAVY = ("numba", "mujoco", "matplotlib", "highspy", "dask", "distributed")
#: Modules of fcso that are not the method: the command line, the schemas and presentation itself (and the facade
#: ``fcso``).
NOT_METHOD = ("fcso.cli", "fcso.schema", "fcso.verify_cli", "fcso.output")
#: Longest module and longest function (its ``def`` to its last line, docstring included), lines: past them a module
#: holds more than one concern, a function more than one step.
MAX_MODULE_LINES = 600
MAX_FUNCTION_LINES = 100
#: Functions allowed to be longer: tables and parsers, read line by line, not followed as steps.
LONG_FUNCTIONS = {"fcsod.cli._parser": "the command line's parser: one add_argument a line"}


def module_name(path: Path) -> str:
    parts = list(path.relative_to(REPO).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def source_modules(packages=PACKAGES) -> dict[str, Path]:
    """Every module of ``packages``: dotted name -> file."""
    return {module_name(path): path for package in packages for path in sorted((REPO / package).rglob("*.py"))}


def _type_checking_block(node: ast.AST) -> bool:
    test = getattr(node, "test", None)
    return isinstance(node, ast.If) and (
        (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING")
        or (isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")
    )


def imports_of(name: str, path: Path, known: set[str]) -> list[tuple[str, list[str], int]]:
    """What module ``name`` imports: (module, names taken from it, line), relative imports resolved.

    ``from package import module`` counts as importing ``package.module``.
    """
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = []

    def visit(node: ast.AST) -> None:
        for child in ast.iter_child_nodes(node):
            if _type_checking_block(child):
                continue
            if isinstance(child, ast.Import):
                found.extend((alias.name, [], child.lineno) for alias in child.names)
            elif isinstance(child, ast.ImportFrom):
                base = child.module or ""
                if child.level:
                    anchor = package.split(".")
                    anchor = anchor[: len(anchor) - (child.level - 1)]
                    base = ".".join(anchor + ([base] if base else []))
                names = [alias.name for alias in child.names]
                submodules = [f"{base}.{n}" for n in names if f"{base}.{n}" in known]
                found.extend((module, [], child.lineno) for module in submodules)
                rest = [n for n in names if f"{base}.{n}" not in known]
                if rest or not submodules:
                    found.append((base, rest, child.lineno))
            visit(child)

    visit(ast.parse(path.read_text(encoding="utf-8"), str(path)))
    return found


def import_graph(packages=PACKAGES) -> dict[str, set[str]]:
    """Module -> the modules of ``packages`` it imports, with the subpackages' ``__init__`` its imports run.

    The top-level packages' ``__init__`` files are facades that import the
    public API; every module runs them, so they are left out of the graph.
    """
    modules = source_modules(packages)
    known = set(modules)
    graph: dict[str, set[str]] = {name: set() for name in modules}
    for name, path in modules.items():
        for module, _, _ in imports_of(name, path, known):
            if module not in known:
                continue
            # importing a.b.c runs a.b's __init__ (not a's: a facade, see above), unless the
            # importer is inside a.b: then that __init__ is what runs it, or has run
            parts = module.split(".")
            targets = {".".join(parts[:k]) for k in range(2, len(parts) + 1)} & known
            graph[name] |= {t for t in targets if t != name and t not in PACKAGES and not within(name, (t,))}
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def connect(node: str) -> None:
        index[node] = low[node] = len(index)
        stack.append(node)
        on_stack.add(node)
        for target in sorted(graph[node]):
            if target not in index:
                connect(target)
                low[node] = min(low[node], low[target])
            elif target in on_stack:
                low[node] = min(low[node], index[target])
        if low[node] == index[node]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == node:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for node in sorted(graph):
        if node not in index:
            connect(node)
    return found


def within(module: str, prefixes) -> bool:
    return any(module == p or module.startswith(p + ".") for p in prefixes)


def package_of(module: str, package: str) -> str:
    """The part of ``package`` that ``module`` belongs to: its subpackage, or itself when it is a module of the
    package's top level (``fcso.report.models`` -> ``fcso.report``, ``fcso.cli`` -> ``fcso.cli``)."""
    return ".".join(module.split(".")[: package.count(".") + 2])


def package_graph(package: str) -> dict[str, set[str]]:
    """The import graph of ``package`` one level up: its subpackages and top-level modules, and which import which
    (a module of one importing a module of another)."""
    graph: dict[str, set[str]] = {}
    for name, targets in import_graph((package,)).items():
        if name == package:
            continue
        source = package_of(name, package)
        graph.setdefault(source, set())
        graph[source] |= {package_of(t, package) for t in targets} - {source}
    return graph


def modules_loaded_by(entry_point: str, argv: list[str]) -> set[str]:
    """The modules a command loads: ``entry_point`` (``module:function``, the function taking ``argv``) run in a fresh
    interpreter, its ``sys.modules`` read at its end (after the exit of ``--help``, too)."""
    module, function = entry_point.split(":")
    script = (
        "import json, sys\n"
        f"from {module} import {function}\n"
        "try:\n"
        f"    {function}({argv!r})\n"
        "except SystemExit:\n"
        "    pass\n"
        "sys.stderr.write('\\nMODULES ' + json.dumps(sorted(sys.modules)) + '\\n')\n"
    )
    result = subprocess.run([sys.executable, "-c", script], cwd=REPO, capture_output=True, text=True, check=True)
    return set(json.loads(result.stderr.rpartition("MODULES ")[2]))


@pytest.mark.parametrize("package", PACKAGES)
def test_no_import_cycle(package):
    assert cycles(import_graph((package,))) == []


@pytest.mark.parametrize("package", PACKAGES)
def test_no_package_cycle(package):
    """Between the subpackages and top-level modules of a package: a layer imports only layers below it."""
    assert cycles(package_graph(package)) == []


def test_the_package_graph_finds_a_cycle_the_modules_do_not_have(tmp_path, monkeypatch):
    """Two packages that import each other through different modules: no module cycle, a package cycle."""
    for folder, text in {
        "loop": "",
        "loop/low": "",
        "loop/low/model.py": "X = 1\n",
        "loop/low/use.py": "from ..high.page import Y\n",
        "loop/high": "",
        "loop/high/page.py": "from ..low.model import X\n\nY = X\n",
    }.items():
        path = tmp_path / folder
        if path.suffix:
            path.write_text(text)
        else:
            path.mkdir()
            (path / "__init__.py").write_text(text)
    monkeypatch.setattr(sys.modules[__name__], "REPO", tmp_path)
    assert cycles(import_graph(("loop",))) == []
    assert cycles(package_graph("loop")) == [["loop.high", "loop.low"]]


@pytest.mark.parametrize(
    ("entry_point", "argv"),
    [
        ("fcso.cli:main", ["--help"]),
        ("fcso.cli:main", ["design", "--help"]),
        ("fcso.cli:main", ["verify", "--help"]),
    ],
)
def test_a_command_starts_without_the_heavy_libraries(entry_point, argv):
    """The start-up budget as an import list, not a time: a command that does not design, draw or simulate loads
    none of :data:`HEAVY`, nor the pipeline, the finger sets or the pages (the verification's settings are light)."""
    loaded = modules_loaded_by(entry_point, argv)
    assert sorted(m for m in loaded if within(m, (*HEAVY, "fcso.pipeline", "fcso.sets", "fcso.output"))) == []


def test_the_import_list_sees_a_heavy_import(tmp_path):
    """The check above can fail: ``fcso design`` loads the pipeline and numba before it finds its part missing."""
    loaded = modules_loaded_by("fcso.cli:main", ["design", str(tmp_path / "missing.stl"), "--out", str(tmp_path)])
    assert {"numba", "fcso.pipeline"} <= loaded


def test_the_cycle_finder_finds_a_cycle_hidden_in_a_function(tmp_path, monkeypatch):
    """The check above can fail: two modules that import each other, one inside a function, are a cycle."""
    package = tmp_path / "loop"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "a.py").write_text("from .b import g\n\ndef f():\n    return g()\n")
    (package / "b.py").write_text("def g():\n    from .a import f\n    return f\n")
    (package / "c.py").write_text("from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from .a import f\n")
    monkeypatch.setattr(sys.modules[__name__], "REPO", tmp_path)
    assert cycles(import_graph(("loop",))) == [["loop.a", "loop.b"]]


def test_the_method_does_not_import_presentation():
    """fcso's method (everything but the command line, the schemas and fcso.output) imports no page, picture or folder
    code.
    """
    modules = source_modules(("fcso",))
    known = set(modules)
    offending = [
        f"{name} (line {line}) imports {module}"
        for name, path in modules.items()
        if name != "fcso" and not within(name, NOT_METHOD)
        for module, _, line in imports_of(name, path, known)
        if within(module, PRESENTATION) and module != LAYOUT
    ]
    assert offending == []


def test_no_private_name_is_used_outside_its_module():
    """``from x import _name`` across modules of fcso, fcsod, the tests and the benchmarks."""
    files = {
        **source_modules(),
        **{module_name(p): p for folder in ("tests", "benchmarks") for p in (REPO / folder).rglob("*.py")},
    }
    known = set(files)
    offending = [
        f"{name} (line {line}) takes {', '.join(private)} from {module}"
        for name, path in files.items()
        for module, names, line in imports_of(name, path, known)
        if within(module, PACKAGES)
        for private in [[n for n in names if n.startswith("_") and not n.startswith("__")]]
        if private
    ]
    assert offending == []


def long_definitions(packages=PACKAGES) -> list[str]:
    """Modules over :data:`MAX_MODULE_LINES` and functions (methods and nested ones too) over
    :data:`MAX_FUNCTION_LINES` lines of ``packages``, except :data:`LONG_FUNCTIONS`."""
    found = []
    for name, path in source_modules(packages).items():
        source = path.read_text(encoding="utf-8")
        if len(source.splitlines()) > MAX_MODULE_LINES:
            found.append(f"{name}: {len(source.splitlines())} lines")
        for node in ast.walk(ast.parse(source, str(path))):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                length = node.end_lineno - node.lineno + 1
                if length > MAX_FUNCTION_LINES and f"{name}.{node.name}" not in LONG_FUNCTIONS:
                    found.append(f"{name}.{node.name} (line {node.lineno}): {length} lines")
    return found


def test_no_long_module_nor_long_function():
    assert long_definitions() == []


def test_the_length_check_sees_a_long_module_and_a_long_function(tmp_path, monkeypatch):
    package = tmp_path / "longpkg"
    package.mkdir()
    (package / "__init__.py").write_text("")
    (package / "long.py").write_text("def f():\n" + "    x = 1\n" * MAX_FUNCTION_LINES + "\n" * MAX_MODULE_LINES)
    (package / "short.py").write_text("def g():\n" + "    x = 1\n" * (MAX_FUNCTION_LINES - 1))
    monkeypatch.setattr(sys.modules[__name__], "REPO", tmp_path)
    assert long_definitions(("longpkg",)) == [
        f"longpkg.long: {MAX_FUNCTION_LINES + 1 + MAX_MODULE_LINES} lines",
        f"longpkg.long.f (line 1): {MAX_FUNCTION_LINES + 1} lines",
    ]


def test_the_daemon_and_its_small_commands_load_neither_mujoco_nor_matplotlib(tmp_path):
    """The supervisor (its loop, the worker's entry point, the journal's repair) and ``fcsod schema`` run without a
    physics engine or a plotter.
    """
    script = (
        "import sys\n"
        "import fcsod.service.daemon, fcsod.service.journal_repair, fcsod.job.process\n"
        "from fcsod.cli import main\n"
        f"assert main(['schema', '--out', {str(tmp_path)!r}]) == 0\n"
        "print(sorted(m for m in ('mujoco', 'matplotlib') if m in sys.modules))\n"
    )
    result = subprocess.run([sys.executable, "-c", script], cwd=REPO, capture_output=True, text=True, check=True)
    assert result.stdout.strip().splitlines()[-1] == "[]"
    assert any(tmp_path.glob("*.json"))


#: What an fcsod operator command needs none of: fcso's design, simulation and pictures, and the libraries that only
#: they (or the bus) use.
NOT_FOR_OPERATORS = (*HEAVY, "fcso.pipeline", "fcso.sets", "fcso.sim", "fcso.output", "trimesh", "zenoh")


@pytest.fixture(scope="module")
def operator_config(tmp_path_factory):
    """A daemon config whose journal holds one job, so ``fcsod jobs`` lists it rather than stopping early."""
    from fcsod.service.journal import Journal
    from tests.fcsod_helpers import free_port, write_config

    base = tmp_path_factory.mktemp("operator")
    config = write_config(base, free_port())
    (base / "state").mkdir()
    journal = Journal(base / "state" / "journal.sqlite3")
    journal.add("job-1", str(base / "watch" / "job"), "2026-01-01T00:00:00+00:00")
    journal.close()
    return config


@pytest.mark.parametrize(
    "argv",
    [["jobs"], ["jobs", "--json"], ["journal", "check"], ["fingers", "list"], ["cancel", "job-1", "--timeout", "0"]],
)
def test_an_operator_command_loads_neither_the_design_nor_the_heavy_libraries(operator_config, argv):
    """The start-up budget of ``fcsod jobs`` and the other operator commands as an import list, not a time."""
    loaded = modules_loaded_by("fcsod.cli:main", [*argv, "--config", str(operator_config)])
    assert sorted(m for m in loaded if within(m, NOT_FOR_OPERATORS)) == []


def test_the_operator_import_list_sees_a_heavy_import(tmp_path):
    """The check above can fail: ``fcsod schema`` writes the verification's schemas, so it loads fcso.sim."""
    assert "fcso.sim" in modules_loaded_by("fcsod.cli:main", ["schema", "--out", str(tmp_path)])
