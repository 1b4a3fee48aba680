"""No Python code calls a kernel compiled without numba's Python wrapper (``INNER_KERNEL``):
such a call jumps through a null pointer and kills the process with a segfault, not an
exception (core/numerics.py). Walks every module of the package; kernels call them, Python
calls their :func:`~ardrone_nmpc.core.numerics.callable_from_python` twins."""

from __future__ import annotations

import ast
import importlib
import pkgutil
import sys
import textwrap
import types

import ardrone_nmpc
from numba.core.dispatcher import Dispatcher


def _is_inner(obj: object) -> bool:
    return isinstance(obj, Dispatcher) and bool(obj.targetoptions.get("no_cpython_wrapper"))


def _compiled(node: ast.AST) -> bool:
    """A ``def`` decorated with numba's ``njit``/``jit`` (any spelling of the call)."""
    for deco in getattr(node, "decorator_list", ()):
        target = deco.func if isinstance(deco, ast.Call) else deco
        name = target.attr if isinstance(target, ast.Attribute) else getattr(target, "id", "")
        if name in ("njit", "jit"):
            return True
    return False


def _resolve(node: ast.expr, namespace: dict) -> object:
    if isinstance(node, ast.Name):
        return namespace.get(node.id)
    if isinstance(node, ast.Attribute):
        owner = _resolve(node.value, namespace)
        if isinstance(owner, types.ModuleType):
            return getattr(owner, node.attr, None)
    return None


def python_calls_of_inner_kernels(module: types.ModuleType) -> list[str]:
    """``module:line name`` for each call, outside compiled functions, of an inner kernel."""
    with open(module.__file__, encoding="utf-8") as source:  # an empty __init__ has no
        tree = ast.parse(source.read())                      # source for inspect
    found: list[str] = []

    def walk(node: ast.AST) -> None:
        for child in ast.iter_child_nodes(node):
            if _compiled(child):
                continue  # kernels may call kernels
            if isinstance(child, ast.Call) and _is_inner(_resolve(child.func, vars(module))):
                found.append(f"{module.__name__}:{child.lineno} {ast.unparse(child.func)}")
            walk(child)

    walk(tree)
    return found


def _package_modules() -> list[types.ModuleType]:
    names = [info.name for info in pkgutil.walk_packages(ardrone_nmpc.__path__, "ardrone_nmpc.")]
    return [importlib.import_module(name) for name in ["ardrone_nmpc", *names]]


def test_no_python_code_calls_an_inner_kernel():
    modules = _package_modules()
    inner = [obj for module in modules for obj in vars(module).values() if _is_inner(obj)]
    assert len(inner) >= 5, "the walk found no inner kernels: it would prove nothing"
    calls = [call for module in modules for call in python_calls_of_inner_kernels(module)]
    assert calls == [], "these would segfault; call the callable_from_python twin:\n" + \
        "\n".join(calls)


def test_the_walk_finds_a_python_call_of_an_inner_kernel(tmp_path, monkeypatch):
    source = textwrap.dedent('''
        from numba import njit
        from ardrone_nmpc.core import sorted_search
        from ardrone_nmpc.core.sorted_search import count_at_or_below

        @njit(cache=False)
        def fine(a):
            return count_at_or_below(a, 2, 0.5)

        def crashes(a):
            return sorted_search.count_at_or_below(a, 2, 0.5) + count_at_or_below(a, 2, 0.5)
    ''')
    (tmp_path / "inner_probe.py").write_text(source)
    monkeypatch.syspath_prepend(str(tmp_path))
    module = importlib.import_module("inner_probe")
    try:
        calls = python_calls_of_inner_kernels(module)
    finally:
        sys.modules.pop("inner_probe", None)
    assert calls == ["inner_probe:11 sorted_search.count_at_or_below",
                     "inner_probe:11 count_at_or_below"]
