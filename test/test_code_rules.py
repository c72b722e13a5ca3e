"""Rules of the code read from the source with `ast`: no compiled function takes more than
MAX_COMPILED_PARAMETERS parameters (the kernel's records, model, data, inputs, take the place
of its arrays), and no two functions of the package have the same body: each has one home.
"""
from __future__ import annotations

import ast
import hashlib
from pathlib import Path

import gyro_sim

ROOT = Path(gyro_sim.__file__).resolve().parent
#: the most parameters a compiled function takes
MAX_COMPILED_PARAMETERS = 12
#: decorators that compile a function with numba (gyro_sim.jit's and the modules' names for them)
COMPILING = ("njit", "_njit", "_njit_inline", "_njit_alloc", "_njit_uncounted", "jit.inline_ir")
#: functions compiled as C functions (gyro_sim.jit.c_address), which take scalars and addresses
C_ENTRIES = ("_kernel_entry", "_null_entry", "_canonical_entry", "_heavy_entry")
#: the C entry over the addresses of the heavy-subtree elimination's arrays (scalars only)
C_ENTRY_ASIDE = {"gyro_sim/dynamics/kernel.py:_heavy_entry"}


def _functions(root: Path = ROOT):
    """(file relative to the package's parent, function node) of every function under root."""
    for path in sorted(root.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), str(path))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                yield path, node


def parameters(node) -> int:
    a = node.args
    return len(a.posonlyargs) + len(a.args) + len(a.kwonlyargs) + (a.vararg is not None) + (a.kwarg is not None)


def compiled(node) -> bool:
    """Is `node` compiled by numba (a compiling decorator, or a C entry)?"""
    names = [ast.unparse(d.func if isinstance(d, ast.Call) else d) for d in node.decorator_list]
    return node.name in C_ENTRIES or any(n in COMPILING for n in names)


def long_compiled(root: Path = ROOT) -> dict[str, int]:
    """"file:function" -> parameters of every compiled function over MAX_COMPILED_PARAMETERS."""
    out = {}
    for path, node in _functions(root):
        if compiled(node) and parameters(node) > MAX_COMPILED_PARAMETERS:
            out[f"{path.relative_to(root.parent).as_posix()}:{node.name}"] = parameters(node)
    return out


def _trivial(statement) -> bool:
    """A `pass`, a constant (a docstring, `...`), or a `return` of nothing or of a constant."""
    if isinstance(statement, ast.Pass):
        return True
    if isinstance(statement, ast.Expr):
        return isinstance(statement.value, ast.Constant)
    return isinstance(statement, ast.Return) and (statement.value is None or isinstance(statement.value, ast.Constant))


def body_hash(node) -> str | None:
    """A digest of a function's parameters and body, its docstring left out (None: an empty
    body, or one trivial statement: `pass`, `...`, a `return` of nothing or of a constant)."""
    body = node.body
    if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant):
        body = body[1:]
    if not body or (len(body) == 1 and _trivial(body[0])):
        return None
    text = ast.dump(node.args) + ast.dump(ast.Module(body=body, type_ignores=[]))
    return hashlib.sha256(text.encode()).hexdigest()


def duplicate_bodies(root: Path = ROOT) -> list[list[str]]:
    """Groups of functions (anywhere under root) whose parameters and bodies are the same."""
    seen: dict[str, list[str]] = {}
    for path, node in _functions(root):
        rel = path.relative_to(root).as_posix()
        h = body_hash(node)
        if h is not None:
            seen.setdefault(h, []).append(f"{rel}:{node.name}")
    return [v for v in seen.values() if len(v) > 1]


def test_the_checks_see_what_they_look_for(tmp_path):
    pkg = tmp_path / "gyro_sim"
    (pkg / "dynamics").mkdir(parents=True)
    (pkg / "dynamics" / "a.py").write_text(
        "@_njit\ndef long(a, b, c, d, e, f, g, h, i, j, k, l, m):\n    x = 1\n    return x + a\n\n"
        "def plain(a, b, c, d, e, f, g, h, i, j, k, l, m):\n    x = 1\n    return x + a\n\n"
        "@jit.inline_ir\ndef short(a):\n    '''doc'''\n    x = 1\n    return x + a\n")
    (pkg / "dynamics" / "b.py").write_text("def twin(a):\n    '''other doc'''\n    x = 1\n    return x + a\n")
    (pkg / "ros").mkdir()
    (pkg / "ros" / "c.py").write_text(
        "class A:\n    def __enter__(self):\n        return self\n\n    def stop(self):\n        pass\n\n"
        "    def size(self):\n        return 0\n\n\n"
        "class B:\n    def __enter__(self):\n        return self\n\n    def stop(self):\n        pass\n\n"
        "    def size(self):\n        return 0\n")
    assert long_compiled(pkg) == {"gyro_sim/dynamics/a.py:long": 13}
    assert sorted(map(sorted, duplicate_bodies(pkg))) == [["dynamics/a.py:long", "dynamics/a.py:plain"],
                                                         ["dynamics/a.py:short", "dynamics/b.py:twin"],
                                                         ["ros/c.py:__enter__", "ros/c.py:__enter__"]]


def test_no_compiled_function_takes_more_than_twelve_parameters():
    """The C entry over the heavy path's addresses aside."""
    assert {k: v for k, v in long_compiled().items() if k not in C_ENTRY_ASIDE} == {}


def test_no_two_functions_of_the_package_have_the_same_body():
    assert duplicate_bodies() == []
