"""The core's module imports: no cycles, function-local imports of sitframe modules only
where they buy start-up time (said in a comment)."""

from __future__ import annotations

import ast
from pathlib import Path

import sitframe

ROOT = Path(sitframe.__file__).parent


def _modules() -> dict[str, Path]:
    out = {}
    for p in ROOT.rglob("*.py"):
        parts = ("sitframe", *p.relative_to(ROOT).with_suffix("").parts)
        out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = p
    return out


def _imports(path: Path, mods: dict[str, Path]) -> list[tuple[str, bool, int]]:
    """(module, function-local?, line) of each sitframe import outside ``TYPE_CHECKING``."""
    out: list[tuple[str, bool, int]] = []

    def target(name: str) -> str | None:
        while name and name not in mods:
            name = name.rpartition(".")[0]
        return name if name and name != "sitframe" else None

    def walk(node: ast.AST, local: bool) -> None:
        for ch in ast.iter_child_nodes(node):
            if isinstance(ch, ast.If) and "TYPE_CHECKING" in ast.unparse(ch.test):
                continue
            if isinstance(ch, ast.Import | ast.ImportFrom):
                if isinstance(ch, ast.ImportFrom) and ch.module == "sitframe":
                    names = [f"sitframe.{a.name}" for a in ch.names]
                elif isinstance(ch, ast.ImportFrom):
                    names = [ch.module or ""]
                else:
                    names = [a.name for a in ch.names]
                out.extend((t, local, ch.lineno) for n in names if (t := target(n)))
            walk(ch, local or isinstance(ch, ast.FunctionDef | ast.AsyncFunctionDef))

    walk(ast.parse(path.read_text()), False)
    return out


def _grimp_graph(type_checking: bool) -> dict[str, set[str]]:
    """Module -> the sitframe modules it imports, as import-linter reads them: ``from
    sitframe.sim import geometry`` is an import of ``sitframe.sim.geometry``, and imports
    inside functions count (``type_checking``: those under ``TYPE_CHECKING`` too)."""
    import grimp

    g = grimp.build_graph("sitframe", include_external_packages=False, cache_dir=None,
                          exclude_type_checking_imports=not type_checking)
    ours = set(_modules())  # (sitframe's __path__ also holds the checkout, for its plugins)
    return {m: (set(g.find_modules_directly_imported_by(m)) & ours) - {m} for m in ours}


def test_no_import_cycles_in_the_core():
    """Counting function-local imports and those only type checkers follow: a cycle hidden
    in a function or behind ``TYPE_CHECKING`` is still a cycle."""
    graph = _grimp_graph(type_checking=True)
    state: dict[str, int] = {}  # 1 = on the path, 2 = done
    path: list[str] = []

    def visit(m: str) -> None:
        state[m] = 1
        path.append(m)
        for d in sorted(graph[m]):
            assert state.get(d) != 1, "import cycle: " + " -> ".join(
                [*path[path.index(d):], d])
            if d not in state:
                visit(d)
        path.pop()
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m)


def test_no_episode_module_in_the_core():
    assert not (ROOT / "episodes.py").exists()


def test_function_local_imports_say_they_buy_start_up_time():
    """A function-local import of a sitframe module has a comment on its line, or its module
    says (``# start-up time:``) why it defers imports."""
    mods = _modules()
    bare = []
    for p in mods.values():
        text = p.read_text()
        lines = text.splitlines()
        if "# start-up time:" in text:
            continue
        bare += [f"{p.name}:{n}" for _t, local, n in _imports(p, mods)
                 if local and "#" not in lines[n - 1]]
    assert not bare, bare


def test_no_chain_of_imports_is_longer_than_ten_modules():
    """The layers keep paths short: a module reaches the bottom of the house in at most ten
    modules (the imports that run, function-local ones counted). A longer chain means a
    layer grew a staircase."""
    graph = _grimp_graph(type_checking=False)
    longest: dict[str, list[str]] = {}

    def chain(m: str) -> list[str]:
        if m not in longest:
            longest[m] = [m, *max((chain(d) for d in graph[m]), key=len, default=[])]
        return longest[m]

    worst = max((chain(m) for m in graph), key=len)
    assert len(worst) <= 10, " -> ".join(worst)


def test_the_top_level_is_the_ground_floor_and_the_subpackages():
    """sitframe/ holds the public face (and ``python -m sitframe``), the ground floor (errors,
    params, scratch), one subpackage per job and the presets: fourteen entries besides data
    folders.
    A new module belongs in the subpackage of its job."""
    entries = sorted(p.name for p in ROOT.iterdir() if p.name != "__pycache__")
    subpackages = ["analysis", "cli", "contract", "gym", "learning", "logs", "runs", "sim",
                   "situations"]
    assert entries == sorted(["__init__.py", "__main__.py", "errors.py", "params.py",
                              "scratch.py", "presets", *subpackages])
    for sub in subpackages:  # each says its job, what it may import and its entry points
        doc = ast.get_docstring(ast.parse((ROOT / sub / "__init__.py").read_text())) or ""
        assert "may import" in doc and "Entry points" in doc, sub


def test_modules_over_700_lines_say_why():
    """A module over 700 lines says in its docstring why it is one module."""
    long = [str(p.relative_to(ROOT)) for p in _modules().values()
            if len(p.read_text().splitlines()) > 700
            and "Why one module" not in (ast.get_docstring(ast.parse(p.read_text())) or "")]
    assert not long, long


def test_the_import_layers_are_kept():
    """import-linter's contracts (pyproject.toml, [tool.importlinter]) all hold: the command
    line on top, the simulator at the bottom, plugins through the public face only."""
    import shutil
    import subprocess

    exe = shutil.which("lint-imports")
    assert exe, "import-linter is part of the test extra"
    res = subprocess.run([exe, "--no-cache"], cwd=ROOT.parent, capture_output=True, text=True)
    assert res.returncode == 0, res.stdout[-2000:]
    assert "broken" in res.stdout and " 0 broken" in res.stdout
