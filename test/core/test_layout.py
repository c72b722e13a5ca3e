"""The package's layout: its imports form no cycle, the ODE system sits between the simulator
and the compiled kernels, and no core module drives another object's private members (the
"auto" integrator steps its inner methods through their public single step).

Read from the source with `ast`, imports inside functions included: a deferred import is still
a dependency.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

import gyro_sim

ROOT = Path(gyro_sim.__file__).resolve().parent
PACKAGE = "gyro_sim"
#: the ROS-free core: scene, dynamics, closed forms, integrators and the Simulator over them
CORE = ("gyro_sim.scene", "gyro_sim.dynamics", "gyro_sim.analytic", "gyro_sim.integrators",
        "gyro_sim.simulator", "gyro_sim.snapshot", "gyro_sim.jit")


def _modules() -> dict[str, Path]:
    """Dotted name -> file of every module of gyro_sim (packages by their __init__)."""
    out = {}
    for path in sorted(ROOT.rglob("*.py")):
        parts = path.relative_to(ROOT).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join((PACKAGE, *parts))] = path
    return out


def import_graph() -> dict[str, set[str]]:
    """Module -> the gyro_sim modules it imports (anywhere in its source)."""
    modules = _modules()
    graph = {}
    for name, path in modules.items():
        is_package = path.name == "__init__.py"
        edges = set()
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                if node.level:
                    base = name.split(".")
                    base = base[:len(base) - node.level + (1 if is_package else 0)]
                    base = ".".join(base + ([node.module] if node.module else []))
                else:
                    base = node.module
                # `from pkg import mod` imports the module pkg.mod
                targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in modules else base
                           for a in node.names]
            else:
                continue
            edges.update(t for t in targets if t in modules and t != name)
        graph[name] = edges
    return graph


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """A cycle [a, b, ..., a] of the directed graph, or None."""
    WHITE, GREY, BLACK = 0, 1, 2
    color = dict.fromkeys(graph, WHITE)
    stack: list[str] = []

    def visit(u):
        color[u] = GREY
        stack.append(u)
        for v in sorted(graph.get(u, ())):
            if color.get(v, WHITE) == GREY:
                return stack[stack.index(v):] + [v]
            if color.get(v, WHITE) == WHITE:
                found = visit(v)
                if found:
                    return found
        stack.pop()
        color[u] = BLACK
        return None

    for u in sorted(graph):
        if color[u] == WHITE:
            found = visit(u)
            if found:
                return found
    return None


def test_cycle_finder_finds_cycles():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b", "c"}, "b": {"c"}, "c": set()}) is None


def test_graph_sees_relative_and_deferred_imports():
    g = import_graph()
    assert "gyro_sim.integrators.dop853.driver" in g["gyro_sim.integrators.auto"]
    assert "gyro_sim.integrators.lie4.kernels" in g["gyro_sim.integrators.lie4.driver"]
    assert "gyro_sim.dynamics.reference" in g["gyro_sim.dynamics.system"]
    assert "gyro_sim.scene.load" in g["gyro_sim.simulator"]  # inside Simulator.__init__


def test_package_imports_have_no_cycle():
    assert find_cycle(import_graph()) is None


def test_simulator_system_kernels_in_one_direction():
    """simulator -> system -> kernel: the kernels know neither the system nor the simulator,
    and the integrators' drivers know the system only by its protocol (no runtime import);
    only their compiled loops call the kernel."""
    g = import_graph()
    simulator, system, kernel = "gyro_sim.simulator", "gyro_sim.dynamics.system", "gyro_sim.dynamics.kernel"
    assert system in g[simulator]
    assert kernel in g[system]
    assert not g[kernel] & {system, simulator}
    assert kernel not in g[simulator]  # the simulator asks the system module
    drivers = [m for m in g if m.startswith("gyro_sim.integrators.") and not m.endswith((".loop", ".kernels"))
               and m != "gyro_sim.warmup"]
    assert "gyro_sim.integrators.rk4.driver" in drivers and "gyro_sim.integrators.gauss4.gauss4s" in drivers
    for m in drivers:
        assert not g[m] & {simulator, kernel, "gyro_sim.dynamics.reference"}, m


def test_core_does_not_import_the_outer_packages():
    """The core (scene, dynamics, integrators, simulator) imports nothing of ros, log, msgs,
    viz, sweep, bench or cli."""
    g = import_graph()
    outer = ("gyro_sim.ros", "gyro_sim.log", "gyro_sim.msgs", "gyro_sim.viz", "gyro_sim.sweep",
             "gyro_sim.bench", "gyro_sim.cli")
    for m, deps in g.items():
        if m.startswith(CORE):
            assert not [d for d in deps if d.startswith(outer)], m


#: the package's layers, lowest first: a module imports only from its own layer or lower ones.
#: numba's policy and the common helpers; the model (scenes, the dynamics, the closed forms);
#: the integrators; the Simulator (and the package's public API, which opens onto it) with the
#: warm-up of its kernels; messages; logs; the node; the reports and sweeps over all of these;
#: the views (which measure themselves on the reports' scenes); the command line
LAYERS = (
    ("gyro_sim.errors", "gyro_sim.jit", "gyro_sim.paths", "gyro_sim.progress", "gyro_sim.safe_paths"),
    ("gyro_sim.scene", "gyro_sim.dynamics", "gyro_sim.analytic"),
    ("gyro_sim.integrators",),
    ("gyro_sim", "gyro_sim.simulator", "gyro_sim.snapshot", "gyro_sim.warmup"),
    ("gyro_sim.msgs",),
    ("gyro_sim.log",),
    ("gyro_sim.ros",),
    ("gyro_sim.sweep", "gyro_sim.bench"),
    ("gyro_sim.viz",),
    ("gyro_sim.cli",),
)


def layer_of(module: str, layers=LAYERS) -> int:
    """The index in `layers` of the longest prefix (a whole dotted part) that `module` starts with."""
    best, rank = -1, None
    for i, prefixes in enumerate(layers):
        for p in prefixes:
            if (module == p or module.startswith(p + ".")) and len(p) > best:
                best, rank = len(p), i
    if rank is None:
        raise KeyError(f"{module} is in no layer")
    return rank


def upward_imports(graph: dict[str, set[str]], layers=LAYERS) -> list[str]:
    """`a -> b` for every import of a module b of a higher layer than a's."""
    return sorted(f"{a} -> {b}" for a, deps in graph.items() for b in deps
                  if layer_of(b, layers) > layer_of(a, layers))


def test_upward_import_finder_sees_them():
    layers = (("p.low",), ("p.high",))
    graph = {"p.low.a": {"p.high.b"}, "p.high.b": {"p.low.c"}, "p.low.c": set()}
    assert upward_imports(graph, layers) == ["p.low.a -> p.high.b"]
    with pytest.raises(KeyError):
        layer_of("q.other", layers)


def test_every_module_has_a_layer():
    for name in import_graph():
        layer_of(name)


def test_no_module_imports_from_a_higher_layer():
    """In particular: numba's policy (gyro_sim.jit) imports nothing of the package, the dynamics
    no integrator, and the log layer neither the node nor the views."""
    assert upward_imports(import_graph()) == []
    assert import_graph()["gyro_sim.jit"] == set()


def _private_reads(path: Path) -> list[str]:
    """`x._name` where x is not self, cls or super(): another object's private member."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if not (isinstance(node, ast.Attribute) and node.attr.startswith("_")
                and not node.attr.startswith("__")):
            continue
        v = node.value
        if isinstance(v, ast.Name) and v.id in ("self", "cls"):
            continue
        if isinstance(v, ast.Call) and isinstance(v.func, ast.Name) and v.func.id == "super":
            continue
        found.append(f"{path.name}:{node.lineno}: {ast.unparse(node)}")
    return found


def test_private_read_detector_sees_them(tmp_path):
    p = tmp_path / "m.py"
    p.write_text("def f(inner):\n    return inner._K, self._K, super()._x, inner.__class__\n")
    assert _private_reads(p) == ["m.py:2: inner._K"]


@pytest.mark.parametrize("name", sorted(m for m in _modules() if m.startswith(CORE)))
def test_no_core_module_reads_another_objects_private_members(name):
    assert _private_reads(_modules()[name]) == []


def _private_imports(path: Path) -> list[str]:
    """`from gyro_sim.x import _name` in the file at `path`: a private name taken across modules."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == PACKAGE:
            found += [f"{path.name}:{node.lineno}: {node.module}.{a.name}" for a in node.names
                      if a.name.startswith("_") and not a.name.startswith("__")]
    return found


def test_private_import_detector_sees_them(tmp_path):
    p = tmp_path / "m.py"
    p.write_text("from gyro_sim.log.mcap_log import CHUNK_SIZE, _plain\nfrom os import _exit\n")
    assert _private_imports(p) == ["m.py:1: gyro_sim.log.mcap_log._plain"]


def test_no_module_imports_a_private_name_of_another():
    assert [f for path in _modules().values() for f in _private_imports(path)] == []
