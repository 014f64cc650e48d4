"""The stub file ``_actrack.pyi`` matches the extension module at runtime.

Two checks: our own comparison (names, properties, parameter names, kinds and defaults, read with
``ast`` from the stub and ``inspect`` from the runtime), which always runs, and mypy's stubtest
when mypy is installed.
"""

from __future__ import annotations

import ast
import inspect
import pathlib
import subprocess
import sys

import pytest

import actrack
from actrack import _actrack

STUB = pathlib.Path(actrack.__file__).with_name("_actrack.pyi")


def stub_tree() -> ast.Module:
    return ast.parse(STUB.read_text())


def public(names):
    return {n for n in names if not n.startswith("_")}


def stub_classes() -> dict[str, ast.ClassDef]:
    return {n.name: n for n in stub_tree().body if isinstance(n, ast.ClassDef)}


def test_stub_and_package_ship_together():
    assert STUB.is_file()
    assert STUB.with_name("py.typed").is_file()


def test_module_names_match():
    tree = stub_tree()
    names = set(stub_classes())
    for node in tree.body:
        if isinstance(node, ast.FunctionDef):
            names.add(node.name)
        if isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            names.add(node.target.id)
    runtime = public(dir(_actrack)) | {"__version__"}
    assert public(names) | {"__version__"} == runtime
    assert set(actrack.__all__) == runtime


def stub_params(fn: ast.FunctionDef, is_method: bool) -> list[tuple[str, str, object]]:
    a = fn.args
    positional = a.posonlyargs + a.args
    if is_method:
        positional = positional[1:]  # self / cls
    defaults = [None] * (len(positional) - len(a.defaults)) + list(a.defaults)
    out = []
    for arg, d in zip(positional, defaults):
        out.append((arg.arg, "POSITIONAL_OR_KEYWORD", ast.literal_eval(d) if d else inspect.Parameter.empty))
    for arg, d in zip(a.kwonlyargs, a.kw_defaults):
        out.append((arg.arg, "KEYWORD_ONLY", ast.literal_eval(d) if d else inspect.Parameter.empty))
    return out


def runtime_params(obj) -> list[tuple[str, str, object]]:
    sig = inspect.signature(obj)
    return [(p.name, p.kind.name, p.default) for p in sig.parameters.values()]


def is_property(node: ast.FunctionDef) -> bool:
    return any(isinstance(d, ast.Name) and d.id == "property" for d in node.decorator_list)


def stub_functions() -> dict[str, ast.FunctionDef]:
    return {n.name: n for n in stub_tree().body if isinstance(n, ast.FunctionDef)}


@pytest.mark.parametrize("name", sorted(stub_functions()))
def test_function_signatures_match(name):
    expected = stub_params(stub_functions()[name], is_method=False)
    assert runtime_params(getattr(_actrack, name)) == expected


@pytest.mark.parametrize("cls_name", sorted(stub_classes()))
def test_class_members_match(cls_name):
    node = stub_classes()[cls_name]
    runtime_cls = getattr(_actrack, cls_name)
    stub_members = {n.name: n for n in node.body if isinstance(n, ast.FunctionDef)}
    if issubclass(runtime_cls, BaseException):
        assert not stub_members
        return
    runtime_members = public(vars(runtime_cls))
    assert public(stub_members) == runtime_members
    for name, fn in stub_members.items():
        if name.startswith("_"):
            continue
        attr = inspect.getattr_static(runtime_cls, name)
        if is_property(fn):
            assert type(attr).__name__ == "getset_descriptor", name
            continue
        assert type(attr).__name__ != "getset_descriptor", f"{name} is a property at runtime"
        bound = getattr(runtime_cls, name)
        is_classmethod = type(attr).__name__ == "classmethod_descriptor"
        expected = stub_params(fn, is_method=True)
        got = runtime_params(bound)
        if not is_classmethod:
            got = got[1:]  # unbound method: drop self
        assert got == expected, name
        stub_is_classmethod = any(
            isinstance(d, ast.Name) and d.id == "classmethod" for d in fn.decorator_list
        )
        assert stub_is_classmethod == is_classmethod, name


def test_mypy_stubtest():
    pytest.importorskip("mypy")
    result = subprocess.run(
        [sys.executable, "-m", "mypy.stubtest", "actrack._actrack", "--ignore-missing-stub"],
        capture_output=True,
        text=True,
        check=False,
    )
    assert result.returncode == 0, result.stdout + result.stderr
