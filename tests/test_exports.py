"""Each package's public names: ``__all__``, re-exported lazily from its modules (PEP 562, SPEC 1), and
importing the packages loads no numerics."""

from __future__ import annotations

import ast
import importlib
import json
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
from footnav.pipeline._lazy import lazy_exports

ROOT = Path(__file__).resolve().parents[1]
TOPS = ("app", "device", "pipeline", "views")
WITHOUT_EXPORTS = {"footnav.app.commands", "footnav.app.experiments"}
"""Packages whose ``__init__`` re-exports nothing (the CLI imports their modules by name)."""
HEAVY = ("numpy", "numba", "scipy", "rerun", "serial", "bleak", "mcap")


def packages() -> dict[str, Path]:
    """``footnav.*`` package name -> its ``__init__.py``, for every folder of the namespace."""
    return {
        "footnav." + ".".join(init.parent.relative_to(ROOT).parts): init
        for top in TOPS
        for init in sorted((ROOT / top).rglob("__init__.py"))
    }


def declared(package: str, init: Path) -> dict[str, tuple[str, str]]:
    """Name -> (module, attribute) of the relative imports in the ``if TYPE_CHECKING:`` block."""
    found: dict[str, tuple[str, str]] = {}
    for node in ast.parse(init.read_text(encoding="utf-8")).body:
        if isinstance(node, ast.If) and ast.unparse(node.test) == "TYPE_CHECKING":
            for stmt in node.body:
                assert isinstance(stmt, ast.ImportFrom) and stmt.level == 1 and stmt.module, ast.unparse(stmt)
                for alias in stmt.names:
                    found[alias.asname or alias.name] = (f"{package}.{stmt.module}", alias.name)
    return found


EXPORTING = sorted(name for name in packages() if name not in WITHOUT_EXPORTS)


def test_every_package_but_the_listed_ones_declares_exports() -> None:
    assert set(packages()) - set(EXPORTING) == WITHOUT_EXPORTS
    assert all(declared(name, packages()[name]) for name in EXPORTING)


@pytest.mark.parametrize("package", EXPORTING)
def test_public_names_resolve_to_their_modules_objects(package: str) -> None:
    pkg = importlib.import_module(package)
    names = declared(package, packages()[package])
    assert pkg.__all__ == list(names)
    folder = packages()[package].parent
    submodules = {p.stem for p in folder.glob("*.py")} | {p.parent.name for p in folder.glob("*/__init__.py")}
    for name, (module, attribute) in names.items():
        assert not name.startswith("_"), name
        assert name not in submodules, f"{package}.{name} would be shadowed by the submodule of that name"
        assert getattr(pkg, name) is getattr(importlib.import_module(module), attribute), name
        assert vars(pkg)[name] is getattr(pkg, name)  # cached in the package's namespace
    assert set(names) <= set(dir(pkg))


@pytest.mark.parametrize("package", sorted(packages()))
def test_an_unknown_name_is_an_attribute_error_naming_the_package(package: str) -> None:
    pkg = importlib.import_module(package)
    with pytest.raises(AttributeError, match=rf"'{package}' has no attribute 'no_such_name'"):
        _ = pkg.no_such_name


def test_submodules_are_still_imported_by_from_import() -> None:
    from footnav.device.links import ble
    from footnav.pipeline.navigation import eskf

    assert eskf.__name__ == "footnav.pipeline.navigation.eskf"
    assert ble.__name__ == "footnav.device.links.ble"


def test_importing_every_package_loads_no_numerics_and_no_exported_module() -> None:
    """In a fresh interpreter: importing all packages loads no numerics, serial, BLE, capture or
    Rerun library and none of the modules that the exports come from; each name then loads its module."""
    exports = {pkg: declared(pkg, packages()[pkg]) for pkg in EXPORTING}
    code = textwrap.dedent(
        f"""
        import importlib, json, sys
        exports = json.loads({json.dumps(json.dumps(exports))})
        for pkg in {sorted(packages())!r}:
            importlib.import_module(pkg)
        heavy = [m for m in {HEAVY!r} if m in sys.modules]
        early = sorted({{m for names in exports.values() for m, _ in names.values() if m in sys.modules}})
        missed = []
        for pkg, names in exports.items():
            for name, (module, _) in names.items():
                getattr(sys.modules[pkg], name)
                if module not in sys.modules:
                    missed.append(f"{{pkg}}.{{name}}")
        print(json.dumps({{"heavy": heavy, "early": early, "missed": missed}}))
        """
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert json.loads(out.stdout) == {"heavy": [], "early": [], "missed": []}


def test_a_name_imports_its_module_on_first_use_only() -> None:
    code = (
        "import sys, footnav.pipeline.navigation as nav\n"
        "before = 'footnav.pipeline.navigation.navigator' in sys.modules\n"
        "from footnav.pipeline.navigation import Navigator\n"
        "print(before, 'footnav.pipeline.navigation.navigator' in sys.modules, Navigator.__module__)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["False", "True", "footnav.pipeline.navigation.navigator"]


def test_lazy_exports_reads_aliases_and_skips_absolute_imports(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    package = tmp_path / "lazy_probe"
    package.mkdir()
    (package / "mod.py").write_text("VALUE = 1\nOTHER = 2\n")
    init = package / "__init__.py"
    init.write_text(
        "from typing import TYPE_CHECKING\n"
        "if TYPE_CHECKING:\n"
        "    from pathlib import Path\n"
        "    from .mod import VALUE as VALUE\n"
        "    from .mod import OTHER as RENAMED\n"
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    module = importlib.import_module("lazy_probe")
    try:
        public, getattr_, dir_ = lazy_exports("lazy_probe", str(init))
        assert public == ["VALUE", "RENAMED"]
        assert "lazy_probe.mod" not in sys.modules
        assert (getattr_("VALUE"), getattr_("RENAMED")) == (1, 2)
        assert vars(module)["RENAMED"] == 2
        assert {"VALUE", "RENAMED"} <= set(dir_())
        with pytest.raises(AttributeError, match="'lazy_probe' has no attribute 'Path'") as caught:
            getattr_("Path")
        assert caught.value.name == "Path" and caught.value.obj is module
    finally:
        sys.modules.pop("lazy_probe.mod", None)
        sys.modules.pop("lazy_probe", None)
