"""What each command imports, in a fresh interpreter: heavy modules only where needed,
and modules that depend on each other one way only."""

from __future__ import annotations

import ast
import json
import os
import subprocess
import sys
from collections.abc import Collection, Iterator
from pathlib import Path

import pytest

from conftest import lens_xml

HEAVY = ("numpy", "pandas", "matplotlib", "scipy", "lxml")

# Runs the command line in this interpreter as the console command does (a
# plain scan without click, the rest through it), then prints every module.
RUN_AND_LIST = (
    "import json, sys\n"
    "from lensaudit.console import dispatch\n"
    "status = dispatch(sys.argv[1:])\n"
    "assert not status, status\n"
    "print(json.dumps(sorted(sys.modules)))\n"
)


def imported_by(
    arguments: list[str], cache_dir: Path, watched: tuple[str, ...] = HEAVY
) -> set[str]:
    """The ``watched`` modules a fresh `lensaudit ARGUMENTS` has imported when it ends."""
    env = dict(os.environ, LENSAUDIT_CACHE_DIR=str(cache_dir))
    done = subprocess.run(
        [sys.executable, "-c", RUN_AND_LIST, *arguments],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    return set(json.loads(done.stdout.splitlines()[-1])) & set(watched)


def imported_modules(statement: str) -> set[str]:
    """Every module a fresh interpreter has imported after ``statement``."""
    code = f"import json, sys\n{statement}\nprint(json.dumps(sorted(sys.modules)))"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return set(json.loads(done.stdout))


@pytest.fixture
def cache_dir(tmp_path: Path) -> Path:
    return tmp_path / "cache"


@pytest.mark.parametrize("output_format", ["table", "csv", "json"])
def test_a_scan_never_imports_pandas_or_matplotlib(cache_dir, output_format):
    found = imported_by(["scan", "-f", output_format, "-o", os.devnull], cache_dir)
    assert "lxml" in found  # parsed: the check can fail
    assert not found & {"pandas", "matplotlib", "scipy"}


@pytest.mark.parametrize("output_format", ["table", "csv", "json"])
def test_a_cold_scan_of_the_bundled_database_audits_without_numpy(cache_dir, output_format):
    found = imported_by(["scan", "-f", output_format, "-o", os.devnull, "--no-cache"], cache_dir)
    assert found == {"lxml"}


def test_a_scan_imports_numpy_for_entries_the_plain_path_leaves_to_it(cache_dir, tmp_path):
    # 1 - 3 w + 2.25 w^2 = (1 - 1.5 w)^2 touches zero: the fast path cannot tell
    # its sign there, the exact path of the array code decides it.
    database = tmp_path / "db"
    database.mkdir()
    (database / "tangent.xml").write_text(
        "<lensdatabase><lens><maker>M</maker><model>L</model><mount>X</mount>"
        '<calibration><distortion model="poly5" focal="10" k1="-1" k2="0.45"/>'
        "</calibration></lens></lensdatabase>"
    )
    found = imported_by(["scan", str(database), "-o", os.devnull], cache_dir)
    assert "numpy" in found


@pytest.mark.parametrize("output_format", ["table", "csv", "json"])
def test_a_warm_scan_imports_no_heavy_module(cache_dir, output_format):
    arguments = ["scan", "-f", output_format, "-o", os.devnull]
    imported_by(arguments, cache_dir)  # fills the cache
    assert imported_by(arguments, cache_dir) == set()


@pytest.mark.parametrize("output_format", ["table", "csv", "json"])
def test_a_warm_scan_does_not_import_typing_dataclasses_or_inspect(cache_dir, output_format):
    # lensaudit's modules name types only for type checkers, and the records a
    # scan makes are not dataclasses (dataclasses imports inspect); lxml imports
    # typing and inspect, but a scan from the cache has no XML to parse.
    arguments = ["scan", "-f", output_format, "-o", os.devnull]
    imported_by(arguments, cache_dir)  # fills the cache
    watched = ("typing", "lxml", "dataclasses", "inspect")
    assert imported_by(arguments, cache_dir, watched) == set()
    assert "typing" in imported_by(arguments + ["--no-cache"], cache_dir, ("typing",))


def test_a_warm_scan_in_another_format_imports_no_heavy_module(cache_dir):
    imported_by(["scan", "-f", "csv", "-o", os.devnull], cache_dir)
    assert imported_by(["scan", "-f", "json", "-o", os.devnull], cache_dir) == set()


@pytest.mark.parametrize("command", ["scan", "report", "plot", "check", "history", "project"])
def test_help_imports_no_plotting_or_data_frames(cache_dir, command):
    found = imported_by([command, "--help"], cache_dir)
    assert not found & {"pandas", "matplotlib"}


def test_report_help_imports_no_heavy_module(cache_dir):
    assert imported_by(["report", "--help"], cache_dir) == set()


def test_the_reader_and_its_cache_import_neither_the_pipeline_nor_a_heavy_module():
    # lxml is imported when a file is parsed, not before: a warm scan never needs it.
    found = imported_modules("import lensaudit.read, lensaudit.read.cache")
    assert "lensaudit.read.cache" in found
    assert not found & {"lensaudit.pipeline", *HEAVY}
    # Gyroflow's reader (and its json) only where a Gyroflow profile is read.
    assert "lensaudit.read.gyroflow" not in found


def test_the_check_reads_its_files_before_it_needs_numpy():
    # The rules import numpy; a check imports it while its files are read
    # (lensaudit.check.check), so importing the package or reading must not.
    found = imported_modules(
        "import lensaudit.check, lensaudit.cli.check\n"
        "from lensaudit.check.inputs import sources_from_paths\n"
        "from lensaudit.check.parsing import parse_sources\n"
        "from lensaudit.read import resolve\n"
        "read = parse_sources(sources_from_paths(resolve(None).paths))\n"
        "assert read and all(f.problem is None for f in read)"
    )
    assert "lxml" in found and "numpy" not in found
    found = imported_modules("from lensaudit.check import analyse")
    assert "lensaudit.check.findings" in found and "numpy" in found


def test_the_summary_does_not_import_the_pipeline_or_numpy():
    found = imported_modules("import lensaudit.summary")
    assert "lensaudit.summary" in found
    assert not found & {"lensaudit.pipeline", *HEAVY}


def test_the_output_formats_do_not_import_the_pipeline():
    found = imported_modules(
        "import lensaudit.formats.csv_format, lensaudit.formats.json_format, "
        "lensaudit.formats.table"
    )
    assert "lensaudit.formats.json_format" in found and "lensaudit.pipeline" not in found


def test_the_column_names_import_no_other_lensaudit_module():
    found = imported_modules("import lensaudit.columns")
    assert {m for m in found if m.startswith("lensaudit")} == {
        "lensaudit",  # the package, and the version it names
        "lensaudit.version",
        "lensaudit.columns",
    }


def test_a_plain_scan_from_the_console_never_imports_click(cache_dir):
    found = imported_by(["scan", "-f", "csv", "-o", os.devnull], cache_dir, ("click", *HEAVY))
    assert "lxml" in found  # it did scan
    assert "click" not in found


# -- the import graph of the source ---------------------------------------------------

SOURCE = Path(__file__).resolve().parents[1] / "src"


def source_modules(root: Path = SOURCE) -> dict[str, tuple[Path, bool]]:
    """Every module of the package in ``root`` (lensaudit's source): name -> (file,
    whether it is a package)."""
    found = {}
    for path in sorted(root.rglob("*.py")):
        parts = list(path.relative_to(root).with_suffix("").parts)
        package = parts[-1] == "__init__"
        found[".".join(parts[:-1] if package else parts)] = (path, package)
    return found


def _when(node: ast.AST, parents: dict[ast.AST, ast.AST]) -> str:
    """When an import runs: "type checking" (under ``if TYPE_CHECKING:``, never),
    "call" (inside a function) or "import" (when the module is imported)."""
    when = "import"
    parent = parents.get(node)
    while parent is not None:
        if isinstance(parent, ast.If) and "TYPE_CHECKING" in ast.unparse(parent.test):
            return "type checking"
        if isinstance(parent, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
            when = "call"
        parent = parents.get(parent)
    return when


def imports(path: Path) -> Iterator[tuple[ast.Import | ast.ImportFrom, str]]:
    """Every import statement of a file, wherever it is, and when it runs."""
    tree = ast.parse(path.read_bytes(), str(path))
    parents = {child: node for node in ast.walk(tree) for child in ast.iter_child_nodes(node)}
    for node in ast.walk(tree):
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            yield node, _when(node, parents)


def imported_module(node: ast.Import | ast.ImportFrom, module: str, package: bool) -> str:
    """The module a ``from`` statement of ``module`` imports from, relative
    ones resolved."""
    if not node.level:
        return node.module or ""
    base = module.split(".") if package else module.split(".")[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join([*base, node.module] if node.module else base)


def modules_named(node: ast.Import | ast.ImportFrom, module: str, package: bool) -> list[str]:
    """The modules an import statement names: those of ``import``, or the one
    ``from`` names."""
    if isinstance(node, ast.Import):
        return [alias.name for alias in node.names]
    return [imported_module(node, module, package)]


def imported_names(
    node: ast.Import | ast.ImportFrom, module: str, package: bool, modules: Collection[str]
) -> list[str]:
    """The ``modules`` an import statement of ``module`` imports: ``from P import
    x`` imports the submodule P.x where there is one, and P for any other name."""
    if isinstance(node, ast.Import):
        return [alias.name for alias in node.names if alias.name in modules]
    source = imported_module(node, module, package)
    found = {f"{source}.{alias.name}" for alias in node.names} & set(modules)
    if len(found) < len(node.names) and source in modules:
        found.add(source)
    return sorted(found)


def import_graph(root: Path = SOURCE) -> dict[str, dict[str, list[str]]]:
    """module -> module of the same source it imports -> where (file:line, when it runs)."""
    modules = source_modules(root)
    graph: dict[str, dict[str, list[str]]] = {name: {} for name in modules}
    for name, (path, package) in modules.items():
        for node, when in imports(path):
            for target in imported_names(node, name, package, modules):
                if target != name:
                    where = f"{path.relative_to(root.parent)}:{node.lineno} ({when})"
                    graph[name].setdefault(target, []).append(where)
    return graph


def cycles(graph: dict[str, dict[str, list[str]]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    found: list[list[str]] = []

    def visit(module: str) -> None:
        index[module] = low[module] = len(index)
        stack.append(module)
        for target in sorted(graph[module]):
            if target not in index:
                visit(target)
                low[module] = min(low[module], low[target])
            elif target in stack:
                low[module] = min(low[module], index[target])
        if low[module] == index[module]:
            component = []
            while not component or component[-1] != module:
                component.append(stack.pop())
            if len(component) > 1:
                found.append(sorted(component))

    for module in sorted(graph):
        if module not in index:
            visit(module)
    return found


def test_the_import_graph_sees_relative_function_level_and_submodule_imports(tmp_path):
    package = tmp_path / "src" / "pkg"
    (package / "sub").mkdir(parents=True)
    files = {
        "__init__.py": "def late():\n    from .sub import deep\n",
        "top.py": "import pkg.sub\nfrom . import other, VALUE\n",
        "other.py": "TYPE_CHECKING = False\nif TYPE_CHECKING:\n    from .top import x\n",
        "sub/__init__.py": "from .. import top\n",
        "sub/deep.py": "from ..other import y\n",
    }
    for name, text in files.items():
        (package / name).write_text(text)
    graph = import_graph(tmp_path / "src")
    assert {name: sorted(targets) for name, targets in graph.items()} == {
        "pkg": ["pkg.sub.deep"],
        "pkg.top": ["pkg", "pkg.other", "pkg.sub"],
        "pkg.other": ["pkg.top"],
        "pkg.sub": ["pkg.top"],
        "pkg.sub.deep": ["pkg.other"],
    }
    assert graph["pkg"]["pkg.sub.deep"] == ["src/pkg/__init__.py:2 (call)"]
    assert graph["pkg.other"]["pkg.top"] == ["src/pkg/other.py:3 (type checking)"]
    assert cycles(graph) == [["pkg", "pkg.other", "pkg.sub", "pkg.sub.deep", "pkg.top"]]
    assert cycles({"a": {"b": []}, "b": {}, "c": {"a": []}}) == []


def test_no_import_cycle_among_lensaudit_modules_counting_function_level_imports():
    """Every import counts, wherever it is: at the top, in a function (it runs
    when called), under ``if TYPE_CHECKING:`` (for type checkers); ``from P
    import x`` imports the submodule P.x where there is one."""
    graph = import_graph()
    found = cycles(graph)
    explained = [
        f"{source} -> {target}: {', '.join(where)}"
        for component in found
        for source in component
        for target, where in sorted(graph[source].items())
        if target in component
    ]
    assert found == [], "import cycles:\n" + "\n".join(explained)


def test_nothing_but_the_reader_imports_lxml():
    reader = SOURCE / "lensaudit" / "read"
    found = []
    for name, (path, package) in source_modules().items():
        for node, when in imports(path):
            named = modules_named(node, name, package)
            lxml = any(n == "lxml" or n.startswith("lxml.") for n in named)
            if lxml and reader not in path.parents:
                found.append(f"{path.relative_to(SOURCE.parent)}:{node.lineno} ({when})")
    assert found == [], "lxml imported outside lensaudit.read:\n" + "\n".join(found)
    # The check can see an import of lxml: the reader's.
    assert any(
        modules_named(node, "lensaudit.read.xml", False) == ["lxml"]
        for node, _ in imports(reader / "xml.py")
    )


def test_a_scan_does_not_load_liblensfuns_rules(cache_dir, tmp_path):
    """What liblensfun refuses is check's question: a scan never imports its rules."""
    arguments = ["scan", "-o", os.devnull, "--no-cache"]
    assert imported_by(arguments, cache_dir, ("lensaudit.read.liblensfun",)) == set()
    database = tmp_path / "db.xml"  # one that passes the check
    database.write_text(lens_xml('<distortion model="poly3" focal="20" k1="0.01"/>'))
    check = ["check", str(database), "-o", os.devnull, "--no-cache"]
    assert imported_by(check, cache_dir, ("lensaudit.read.liblensfun",)) == {
        "lensaudit.read.liblensfun"
    }
