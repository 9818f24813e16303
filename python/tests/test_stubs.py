"""The type stubs describe the compiled module: no name missing, none stale."""

import ast
import pathlib

import tendril
from tendril import _tendril

STUB = pathlib.Path(tendril.__file__).with_name("_tendril.pyi")


def public(names):
    return {n for n in names if not n.startswith("_")}


def test_stub_names_match_the_module():
    tree = ast.parse(STUB.read_text())
    top = {n.name for n in tree.body if isinstance(n, (ast.ClassDef, ast.FunctionDef))}
    assert top == public(dir(_tendril))
    for cls in (n for n in tree.body if isinstance(n, ast.ClassDef)):
        stubbed = public(f.name for f in cls.body if isinstance(f, ast.FunctionDef))
        assert stubbed == public(dir(getattr(_tendril, cls.name))), cls.name
    assert (STUB.parent / "py.typed").is_file()
