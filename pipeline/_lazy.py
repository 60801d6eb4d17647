"""Lazy re-exports for the packages' ``__init__`` modules (PEP 562, Scientific Python SPEC 1)."""

from __future__ import annotations

import ast
import importlib
import importlib.util
import sys
from collections.abc import Callable
from pathlib import Path


def _is_type_checking(test: ast.expr) -> bool:
    """Whether an ``if`` test is ``TYPE_CHECKING`` or ``typing.TYPE_CHECKING``."""
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING"
    )


def _exported(package_name: str, init_file: str) -> dict[str, tuple[str, str]]:
    """Public name -> (module, attribute), from the relative imports of the ``if TYPE_CHECKING:`` blocks."""
    tree = ast.parse(Path(init_file).read_text(encoding="utf-8"), filename=init_file)
    origin: dict[str, tuple[str, str]] = {}
    for block in tree.body:
        if not (isinstance(block, ast.If) and _is_type_checking(block.test)):
            continue
        for stmt in block.body:
            if not (isinstance(stmt, ast.ImportFrom) and stmt.level > 0 and stmt.module):
                continue  # absolute imports there are for annotations only
            module = importlib.util.resolve_name("." * stmt.level + stmt.module, package_name)
            for alias in stmt.names:
                origin[alias.asname or alias.name] = (module, alias.name)
    return origin


def lazy_exports(
    package_name: str, init_file: str
) -> tuple[list[str], Callable[[str], object], Callable[[], list[str]]]:
    """The public names of a package, loaded on first use.

    The names are those that the package's ``__init__.py`` imports relatively (``from .module import
    A as A``) in its ``if TYPE_CHECKING:`` block: type checkers read that block as real imports (the
    redundant alias marks an explicit re-export, PEP 484), and at run time each name becomes a lazy
    attribute (PEP 562 module ``__getattr__``; the convention of Scientific Python SPEC 1 and
    ``lazy_loader``), so importing a package imports none of its modules. The call goes in the block's
    ``else:``, where type checkers do not see the ``__getattr__`` and so still report unknown names.

    Parameters
    ----------
    package_name
        the package's ``__name__``.
    init_file
        the package's ``__file__`` (its ``__init__.py``, read with :mod:`ast`).

    Returns
    -------
    tuple
        ``(__all__, __getattr__, __dir__)`` for the package's namespace. ``__getattr__(name)`` imports
        the name's module, caches the value in the package's namespace (later look-ups do not call it
        again) and returns it; it raises :class:`AttributeError` for any other name (so ``from package
        import submodule`` still imports the submodule). ``__dir__()`` lists the namespace and ``__all__``.

    Examples
    --------
    In ``footnav/pipeline/navigation/__init__.py``::

        from typing import TYPE_CHECKING

        from footnav.pipeline._lazy import lazy_exports

        if TYPE_CHECKING:
            from .navigator import Navigator as Navigator
            from .navigator import navigate as navigate
        else:
            __all__, __getattr__, __dir__ = lazy_exports(__name__, __file__)
    """
    origin = _exported(package_name, init_file)
    public = list(origin)

    def __getattr__(name: str) -> object:  # noqa: N807 - the hook PEP 562 names
        package = sys.modules[package_name]
        if name not in origin:
            raise AttributeError(f"module {package_name!r} has no attribute {name!r}", name=name, obj=package)
        module, attribute = origin[name]
        value = getattr(importlib.import_module(module), attribute)
        vars(package)[name] = value  # later look-ups find it without calling __getattr__
        return value

    def __dir__() -> list[str]:  # noqa: N807 - the hook PEP 562 names
        return sorted(set(vars(sys.modules[package_name])) | set(public))

    return public, __getattr__, __dir__
