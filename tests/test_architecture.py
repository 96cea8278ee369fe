"""The layers of the package point only down, there is no import cycle, the model layer is light,
and the C interface as cffi reads it matches the compiler's layout."""

from __future__ import annotations

import ast
import os
import subprocess
import sys
from pathlib import Path

import pytest

import vgtarm

PACKAGE = Path(vgtarm.__file__).resolve().parent

#: The package's own ``__init__`` (its public names: the whole library, as the command line has it).
ROOT = "__root__"
#: Layers from the bottom up; a module may import its own layer and the layers below.
LAYERS: tuple[frozenset[str], ...] = (
    frozenset(
        {
            "errors",
            "checks",
            "fileio",
            "kinds",
            "memory",
            "markup",
            "machine",
            "progress",
            "version",
            "compiler",
            "option",
        }
    ),
    frozenset({"model"}),
    frozenset({"paths", "ga"}),
    frozenset({"ik", "toolpaths", "drilling"}),
    frozenset({"control"}),
    frozenset({"simulation"}),
    frozenset({"mujoco_bridge", "retiming", "design", "calibration"}),
    frozenset({"experiment"}),
    frozenset({"study", "export"}),
    frozenset({"app"}),
    frozenset({ROOT}),  # the front door: every public name, imported on first use
)
#: Imports a lower layer may make inside a function body, resolved at call time (documented).
ALLOWED_UPWARD = {("model.robot", "ik")}  # Robot.inverse_kinematics, a thin convenience


def _top(module: str) -> str:
    return module.split(".")[0]


def _layer(top: str) -> int:
    for level, names in enumerate(LAYERS):
        if top in names:
            return level
    raise AssertionError(f"vgtarm.{top} belongs to no layer: add it to LAYERS in {__file__}")


def _modules() -> dict[str, Path]:
    found = {}
    for path in PACKAGE.rglob("*.py"):
        parts = path.relative_to(PACKAGE).with_suffix("").parts
        if parts[-1] == "__init__":
            parts = parts[:-1]
        if parts:
            found[".".join(parts)] = path
    return found


def _imports(module: str, path: Path) -> list[tuple[str, bool]]:
    """``(imported vgtarm module, at module level)`` for every import of ``module``."""
    tree = ast.parse(path.read_text())
    package = module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]
    top_level = {id(node) for node in tree.body}
    for node in tree.body:  # imports under `if TYPE_CHECKING:` or try at module level count too
        for child in ast.walk(node):
            if isinstance(child, ast.Import | ast.ImportFrom) and not isinstance(node, ast.FunctionDef | ast.ClassDef):
                top_level.add(id(child))
    found: list[tuple[str, bool]] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - node.level + 1]
                target = ".".join(base + ([node.module] if node.module else []))
            elif node.module and node.module.startswith("vgtarm."):
                target = node.module.removeprefix("vgtarm.")
            else:
                continue
            if node.module is None:  # `from .. import x`: x is a module or a name of the package
                prefix = f"{target}." if target else ""
                targets = [
                    f"{prefix}{alias.name}" if f"{prefix}{alias.name}" in MODULES else (target or ROOT)
                    for alias in node.names
                ]
            else:
                targets = [target]
            found += [(t, id(node) in top_level) for t in targets]
        elif isinstance(node, ast.Import):
            found += [
                (alias.name.removeprefix("vgtarm."), id(node) in top_level)
                for alias in node.names
                if alias.name.startswith("vgtarm.")
            ]
    return found


MODULES = _modules()


@pytest.mark.parametrize(
    "module", sorted(m for m in MODULES if "." in m or m in {"errors", "checks", "fileio", "paths", "ga"})
)
def test_no_module_imports_a_layer_above_it(module):
    own = _layer(_top(module))
    for target, _ in _imports(module, MODULES[module]):
        if (module, _top(target)) in ALLOWED_UPWARD:
            continue
        assert _layer(_top(target)) <= own, f"vgtarm.{module} (layer {own}) imports vgtarm.{target} from a layer above"


def test_the_allowed_upward_import_is_only_inside_a_function():
    for module, target in ALLOWED_UPWARD:
        for imported, at_module_level in _imports(module, MODULES[module]):
            if _top(imported) == target:
                assert not at_module_level, f"vgtarm.{module} imports vgtarm.{imported} at module load"


def _cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """An import cycle of ``graph`` (module -> imported modules), or ``None``."""
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph[node]):
            if state.get(nxt) == 1:
                return stack[stack.index(nxt) :] + [nxt]
            if nxt not in state and (found := visit(nxt)):
                return found
        stack.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state and (found := visit(node)):
            return found
    return None


def _graph(*, inside_functions: bool) -> dict[str, set[str]]:
    """Module -> the vgtarm modules it imports (at module level, or anywhere), leaving out a
    submodule's import of its own package (a package's ``__init__`` importing its submodules is
    not a cycle for them) and the documented upward call."""
    return {
        m: {
            t
            for t, top in _imports(m, p)
            if (top or inside_functions)
            and t in MODULES
            and t != m
            and not m.startswith(t + ".")
            and (m, _top(t)) not in ALLOWED_UPWARD
        }
        for m, p in MODULES.items()
    }


def test_no_import_cycle_among_modules():
    cycle = _cycle(_graph(inside_functions=False))
    assert cycle is None, "import cycle: " + " -> ".join(cycle or [])


def test_no_import_inside_a_function_dodges_a_cycle():
    """An import inside a function may defer a heavy or optional module (the command line loads
    what a command needs), never hide a cycle: with every such import counted as if it were at
    module level, the modules still form no cycle (the one documented upward call aside)."""
    cycle = _cycle(_graph(inside_functions=True))
    assert cycle is None, "import cycle through an import inside a function: " + " -> ".join(cycle or [])


def test_importing_the_model_loads_neither_ik_nor_scipy_optimize():
    code = (
        "import sys, vgtarm.model; "
        "bad = [m for m in sys.modules if m.startswith(('vgtarm.ik', 'vgtarm.control', 'vgtarm.simulation', "
        "'vgtarm.app', 'vgtarm.paths', 'scipy.optimize'))]; print(bad)"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "[]", done.stdout


def test_codegen_refuses_a_duplicate_function_name(monkeypatch):
    from vgtarm.model import codegen

    clash = {next(iter(codegen.model.BUILDERS)): codegen.model.BUILDERS[next(iter(codegen.model.BUILDERS))]}
    monkeypatch.setattr(codegen.control, "BUILDERS", {**codegen.control.BUILDERS, **clash})
    with pytest.raises(RuntimeError, match="duplicate compiled function names"):
        codegen.all_builders()


def _model_imports(relative: str) -> set[str]:
    """Model-package files (relative posix paths) that ``relative`` imports at any depth, following
    the import statements themselves (a package's ``__init__`` only when it is imported by name)."""
    model = PACKAGE / "model"
    seen: set[str] = set()
    todo = [relative]
    while todo:
        current = todo.pop()
        if current in seen:
            continue
        seen.add(current)
        path = model / current
        package = path.parent.relative_to(model).parts
        for node in ast.walk(ast.parse(path.read_text())):
            if not isinstance(node, ast.ImportFrom) or node.level == 0:
                continue
            base = list(package[: len(package) - (node.level - 1)]) if node.level > 1 else list(package)
            if node.level - 1 > len(package):
                continue  # above the model package (errors, fileio): not a model source
            parts = base + (node.module.split(".") if node.module else [])
            candidates = [parts + [alias.name] for alias in node.names] + [parts]
            for candidate in candidates:
                stem = "/".join(candidate)
                for found in (f"{stem}.py", f"{stem}/__init__.py" if candidate != base else ""):
                    if found and (model / found).is_file():
                        todo.append(found)
                        break
    return seen


def test_cache_key_covers_every_source_the_code_generation_reads():
    """Every model file the code generation, the stack definitions and the C interface import (at
    any depth), every C source and the robot data are hashed; what the key skips is runtime only."""
    from vgtarm.model import compiled

    model = PACKAGE / "model"
    sources = {p.relative_to(model).as_posix() for p in compiled.model_sources()}
    roots = ["codegen/__init__.py", "definition.py", "interface.py", "stack/symbolic.py", "stack/description.py"]
    shaping = set().union(*(_model_imports(root) for root in roots))
    separate = {p.relative_to(model).as_posix() for d in compiled.SEPARATE_LIBRARIES for p in (model / d).rglob("*")}
    assert not shaping & separate  # the separate libraries (the recursive model) shape none of these
    shaping |= {p.relative_to(model).as_posix() for p in model.rglob("*") if p.suffix in (".c", ".h", ".toml")}
    shaping -= separate
    assert shaping <= sources, sorted(shaping - sources)
    assert not shaping & compiled.RUNTIME_ONLY
    on_disk = {p.relative_to(model).as_posix() for p in model.rglob("*.py") if "__pycache__" not in p.parts}
    assert on_disk - sources == set(compiled.RUNTIME_ONLY) | {p for p in separate if p.endswith(".py")}
    assert {"codegen/control.py", "symbolic.py", "parameters.py", "csrc/ga.c"} <= shaping  # the walk finds them


def test_cache_key_follows_the_build_recipe(monkeypatch):
    from vgtarm.model import compiling, library_cache

    before = library_cache._cache_key("cc")
    monkeypatch.setattr(compiling, "_STACK_GENERATED_CFLAGS", ("-O3", "-fPIC"))
    assert library_cache._cache_key("cc") != before


def test_c_interface_layout_matches_the_compiler(robot):
    from vgtarm.model import interface
    from vgtarm.model.compiled import CompiledBackend

    if not isinstance(robot.backend, CompiledBackend):
        pytest.skip("no C compiler: the interpreted backend has no C interface")
    compiled = robot.backend.layout()
    python = interface.python_layout()
    fields = interface.layout_fields()
    assert len(compiled) == len(python) == len(fields)
    mismatch = [(f, c, p) for f, c, p in zip(fields, compiled, python, strict=True) if c != p]
    assert not mismatch, f"(structure, field), compiler, cffi: {mismatch}"
    assert compiled[0] > 0


def test_status_and_integrator_codes_come_from_the_header():
    from vgtarm.model import closedloop, interface

    header = interface.HEADER.read_text()
    for name, code in interface.enum("vgt_status").items():
        assert f"{name} = {code}" in header.replace("  ", " ")
    assert closedloop.INTEGRATOR_CODES == {"euler": 0, "semi_implicit_euler": 1, "rk4": 2}


def test_one_cpu_count_sizes_the_workers_and_the_ga_threads():
    """A process pinned to one CPU (its affinity mask, as ``taskset`` sets it) gets one reproduce
    worker and one GA thread; the count is written once (``vgtarm.machine``)."""
    code = (
        "import os; os.sched_setaffinity(0, {min(os.sched_getaffinity(0))}); "
        "from vgtarm.machine import usable_cpus; from vgtarm.app.pool import default_workers; "
        "from vgtarm.model.closedloop import ga_threads; print(usable_cpus(), default_workers(), ga_threads())"
    )
    env = {k: v for k, v in os.environ.items() if k != "VGTARM_THREADS"}
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env)
    assert done.stdout.split() == ["1", "1", "1"]
    sources = [p.read_text() for p in PACKAGE.rglob("*.py") if p.name != "machine.py"]
    assert not [s for s in sources if "sched_getaffinity" in s or "cpu_count(" in s]


#: The longest a function of the package may be (lines, its docstring included): issue 34's bound.
LONGEST_FUNCTION = 80


def test_no_function_of_the_package_is_longer_than_the_bound():
    """Every function and method in ``src/`` is at most :data:`LONGEST_FUNCTION` lines, so that each
    reads on one screen (a long one is split where its steps are)."""
    long = []
    for path in sorted(PACKAGE.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                lines = (node.end_lineno or node.lineno) - node.lineno + 1
                if lines > LONGEST_FUNCTION:
                    long.append(f"{path.relative_to(PACKAGE)}:{node.lineno} {node.name} ({lines} lines)")
    assert not long, long
