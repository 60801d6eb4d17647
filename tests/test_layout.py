"""The house: one ``footnav`` namespace, packages listed in pyproject.toml, layers that import one way,
no import cycles, and a command line whose parser imports no numerics."""

from __future__ import annotations

import ast
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
from footnav.app import choices

ROOT = Path(__file__).resolve().parents[1]
TOPS = ("app", "device", "pipeline", "views")
# what each layer may import of the others (architecture: app -> device, pipeline, views; views -> pipeline;
# device -> pipeline; pipeline -> nothing above it)
ALLOWED = {"app": set(TOPS), "views": {"views", "pipeline"}, "device": {"device", "pipeline"}, "pipeline": {"pipeline"}}


def modules() -> dict[str, Path]:
    found = {}
    for top in TOPS:
        for f in sorted((ROOT / top).rglob("*.py")):
            parts = list(f.relative_to(ROOT).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            found["footnav." + ".".join(parts)] = f
    return found


def module_level_imports(path: Path) -> set[str]:
    """Names imported when the module loads (not inside functions, not under ``TYPE_CHECKING``)."""
    names: set[str] = set()

    def visit(node: ast.AST) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
                continue
            if isinstance(child, ast.If) and "TYPE_CHECKING" in ast.unparse(child.test):
                continue
            if isinstance(child, ast.Import):
                names.update(a.name for a in child.names)
            elif isinstance(child, ast.ImportFrom) and child.module and child.level == 0:
                names.add(child.module)
                names.update(f"{child.module}.{a.name}" for a in child.names)
            visit(child)

    visit(ast.parse(path.read_text(encoding="utf-8")))
    return names


def all_imports(path: Path) -> set[str]:
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
    return names


def test_pyproject_lists_every_package_and_maps_the_namespace() -> None:
    tool = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]
    folders = {
        "footnav." + ".".join(init.parent.relative_to(ROOT).parts)
        for top in TOPS
        for init in (ROOT / top).rglob("__init__.py")
    }
    assert set(tool["packages"]) == folders
    assert tool["package-dir"] == {f"footnav.{top}": top for top in TOPS}


def test_the_old_top_level_names_are_not_importable() -> None:
    for name in TOPS:
        out = subprocess.run(
            [sys.executable, "-c", f"import {name}"], cwd="/", capture_output=True, text=True, check=False
        )
        assert out.returncode != 0 and "ModuleNotFoundError" in out.stderr, name
    out = subprocess.run([sys.executable, "-c", "import footnav.pipeline.navigation"], cwd="/", check=False)
    assert out.returncode == 0


def test_every_import_of_footnav_code_is_by_its_footnav_name() -> None:
    offending = [
        f"{path.relative_to(ROOT)}: {name}"
        for path in [*modules().values(), *ROOT.glob("tests/*.py"), *ROOT.glob("benchmarks/*.py")]
        for name in all_imports(path)
        if name.split(".")[0] in TOPS
    ]
    assert offending == []


def test_layers_import_one_way() -> None:
    offending = []
    for name, path in modules().items():
        layer = name.split(".")[1]
        for imported in all_imports(path):
            if imported.startswith("footnav.") and imported.split(".")[1] not in ALLOWED[layer]:
                offending.append(f"{name} imports {imported}")
    assert offending == []


def test_no_import_cycles_between_modules() -> None:
    found = modules()
    graph = {name: {m for m in module_level_imports(path) if m in found and m != name} for name, path in found.items()}
    state: dict[str, int] = {}  # 1 on the current path, 2 done
    cycles: list[list[str]] = []

    def walk(node: str, path: list[str]) -> None:
        state[node] = 1
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                cycles.append([*path[path.index(nxt) :], nxt])
            elif nxt not in state:
                walk(nxt, [*path, nxt])
        state[node] = 2

    for start in sorted(graph):
        if start not in state:
            walk(start, [start])
    assert cycles == []


def imported_after(statement: str, modules: tuple[str, ...]) -> list[str]:
    """Which of ``modules`` a fresh interpreter holds after running ``statement``."""
    code = f"import sys; {statement}; print(' '.join(m for m in {modules!r} if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return out.stdout.split()


def test_building_the_parser_imports_no_numerics_or_rerun() -> None:
    heavy = ("numpy", "numba", "scipy", "rerun", "serial", "bleak", "mcap")
    assert imported_after("from footnav.app.parser import build_parser; build_parser()", heavy) == []


def test_the_session_commands_import_no_scipy_optimize_or_stats() -> None:
    """``scipy.optimize`` (calibration's fit) and ``scipy.stats`` (the lever-arm check) take about a second
    each to import; a replay, demo, live session or export uses neither until it calibrates or checks."""
    commands = ", ".join(f"footnav.app.commands.{c}" for c in ("replay", "demo", "live", "export"))
    assert imported_after(f"import {commands}", ("scipy.optimize", "scipy.stats")) == []


def test_experiment_help_imports_no_numerics_and_lists_every_experiment() -> None:
    code = (
        "import sys, contextlib, io; from footnav.app.experiments import experiment_parser; "
        "out = io.StringIO()\n"
        "with contextlib.redirect_stdout(out), contextlib.suppress(SystemExit):\n"
        "    experiment_parser(['--help']).parse_args(['--help'])\n"
        "heavy = ('numpy', 'numba', 'scipy', 'rerun'); "
        "print(' '.join(m for m in heavy if m in sys.modules)); print(out.getvalue())"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    imported, _, help_text = out.stdout.partition("\n")
    assert imported == ""
    from footnav.app.experiments import EXPERIMENTS

    assert all(name in help_text for name in EXPERIMENTS)


def test_the_experiments_table_names_every_experiment_module() -> None:
    from footnav.app.experiments import EXPERIMENTS, experiment_module

    folder = ROOT / "app" / "experiments"
    on_disk = {f.stem for f in folder.glob("*.py") if not f.name.startswith("_")}
    assert {module for module, _ in EXPERIMENTS.values()} == on_disk
    for name in EXPERIMENTS:
        module = experiment_module(name)
        assert callable(module.add_arguments) and callable(module.run)


@pytest.mark.parametrize(
    ("names", "module", "table"),
    [
        (choices.IMU_GRADES, "footnav.device.emulator.sensors.imu_errors", "IMU_GRADES"),
        (choices.AXIS_ERRORS, "footnav.device.emulator.sensors.imu_errors", "AXIS_ERRORS"),
        (choices.PROFILES, "footnav.pipeline.navigation.profiles", "PROFILES"),
        (choices.RECORDING_FORMATS, "footnav.device.files.recordings", "LOADERS"),
        (choices.UNIT_MODELS, "footnav.device.models", "UNIT_MODELS"),
    ],
)
def test_the_parsers_choices_are_the_tables_keys(names: tuple[str, ...], module: str, table: str) -> None:
    import importlib

    assert names == tuple(sorted(getattr(importlib.import_module(module), table)))


def test_the_output_modes_are_auto_and_the_units_outputs() -> None:
    from footnav.device.models import OUTPUTS

    assert ("auto", *OUTPUTS) == choices.OUTPUT_MODES


def test_every_emulated_path_can_be_walked() -> None:
    from footnav.device.emulator.motion.gait import simulate_walk

    for path in choices.PATHS:
        assert simulate_walk(path, 2.0, seed=1).t_s.size > 0


MAX_MODULES_PER_FOLDER = 12
MAX_MODULE_LINES = 600
MAX_MODULE_DOCSTRING_LINES = 40
LONG_MODULES = {
    "footnav.device.unit": "one class, the unit driver: start, stream and stop share its state",
}
"""Modules allowed over MAX_MODULE_LINES, each with its reason (also stated in its docstring)."""
GOOGLE_SECTION = re.compile(r"^\s*(Args|Arguments|Returns|Yields|Raises|Attributes):\s*$", re.MULTILINE)


def test_no_folder_holds_more_than_about_twelve_modules() -> None:
    folders: dict[Path, int] = {}
    for path in modules().values():
        if path.name != "__init__.py":
            folders[path.parent] = folders.get(path.parent, 0) + 1
    crowded = {str(f.relative_to(ROOT)): n for f, n in folders.items() if n > MAX_MODULES_PER_FOLDER}
    assert not crowded


def test_long_modules_are_the_listed_ones() -> None:
    lines = {name: len(path.read_text().splitlines()) for name, path in modules().items()}
    long = {name for name, n in lines.items() if n > MAX_MODULE_LINES}
    assert long <= set(LONG_MODULES), {name: lines[name] for name in long - set(LONG_MODULES)}
    assert set(LONG_MODULES) <= long, "a listed module is no longer long: take it off LONG_MODULES"


def test_module_docstrings_are_short_and_docstrings_are_numpydoc() -> None:
    too_long, google = {}, []
    for name, path in modules().items():
        tree = ast.parse(path.read_text())
        doc = ast.get_docstring(tree, clean=False) or ""
        if doc.count("\n") + 1 > MAX_MODULE_DOCSTRING_LINES:
            too_long[name] = doc.count("\n") + 1
        for node in ast.walk(tree):
            if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
                text = ast.get_docstring(node, clean=False)
                if text and GOOGLE_SECTION.search(text):
                    google.append(f"{name}:{getattr(node, 'name', '')}")
    assert not too_long
    assert not google
