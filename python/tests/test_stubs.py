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


def test_stub_parameters_match_the_compiled_signatures():
    import inspect

    tree = ast.parse(STUB.read_text())
    checked = 0
    for cls in (n for n in tree.body if isinstance(n, ast.ClassDef)):
        for f in (f for f in cls.body if isinstance(f, ast.FunctionDef) and not f.name.startswith("_")):
            compiled = getattr(getattr(_tendril, cls.name), f.name)
            if isinstance(compiled, property):
                continue
            try:
                signature = inspect.signature(compiled)
            except (TypeError, ValueError):
                continue  # no text signature (a property getter): names are checked above
            stubbed = [a.arg for a in f.args.args + f.args.kwonlyargs if a.arg not in ("self", "cls")]
            assert stubbed == [p for p in signature.parameters if p not in ("self", "cls", "$self", "$cls")], (
                cls.name, f.name)
            checked += 1
    assert checked >= 5, f"only {checked} signatures could be read"
