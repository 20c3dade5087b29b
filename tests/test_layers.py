"""The package's layers hold at import time (walked with ast over the sources, then imported).

Each folder of ``clcsg/`` is one node, each module at the package root its own; an import at
module level of one of our modules is an edge.  The edges must go down :data:`LAYERS` (a folder
may import itself and anything in a lower layer, never a higher one or one beside it), so there
is no cycle between folders.  Imports inside functions are only for deferring heavy optional
dependencies and what a command does not use; at most :data:`MAX_DEFERRED_OWN` of them import
our own modules.
"""

from __future__ import annotations

import ast
import importlib
import pathlib
import re
import subprocess
import sys

import pytest

ROOT = pathlib.Path(__file__).resolve().parent.parent / "clcsg"

#: bottom to top; a node may import only nodes of its own or a lower layer
LAYERS = (
    ("errors", "progress"),
    ("atomic",),
    ("model",),
    ("cl",),
    ("compile",),
    ("readers",),
    ("sampling",),
    ("writers",),
    ("rendering", "queries", "meshing"),
    ("pipeline",),
    ("viewer", "batching"),
    ("cli",),
)
#: imports of our own modules inside functions: each one defers a cycle the model's
#: conveniences would otherwise make (Scene.compile, Primitive's registry, a probe ray trace)
#: or keeps the sampling commands from loading the renderers (the pipeline's camera and image)
MAX_DEFERRED_OWN = 8


def module_name(path: pathlib.Path) -> str:
    parts = ["clcsg", *path.relative_to(ROOT).with_suffix("").parts]
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def modules() -> list[tuple[str, pathlib.Path]]:
    return sorted((module_name(p), p) for p in ROOT.rglob("*.py"))


def node(module: str) -> str:
    """The layer node of ``clcsg.x.y``: its folder ``x`` (or the root module ``x``)."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


def own_imports(module: str, path: pathlib.Path):
    """(target module, line, at module level?) of every import of ``clcsg`` in the file."""
    tree = ast.parse(path.read_text(encoding="utf-8"))
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    top = set()
    for stmt in tree.body:  # module level, also inside a top-level if/try
        top.update(id(n) for n in ast.walk(stmt) if not isinstance(stmt, (ast.FunctionDef, ast.ClassDef,
                                                                           ast.AsyncFunctionDef)))
    for n in ast.walk(tree):
        if isinstance(n, ast.Import):
            targets = [a.name for a in n.names]
        elif isinstance(n, ast.ImportFrom):
            base = n.module or ""
            if n.level:
                pkg = package.split(".")
                pkg = pkg[: len(pkg) - (n.level - 1)]
                base = ".".join(pkg + ([n.module] if n.module else []))
            targets = [base]
        else:
            continue
        for t in targets:
            # ``from .. import __version__`` names the package itself, loaded before any of its
            # modules anyway (and lazy: its names import their modules on first use)
            if t.startswith("clcsg."):
                yield t, n.lineno, id(n) in top


def test_every_module_level_import_goes_down_the_layers():
    rank = {name: k for k, layer in enumerate(LAYERS) for name in layer}
    bad = []
    for module, path in modules():
        src = node(module)
        if src in ("__init__", "__main__"):  # the facade and ``python -m clcsg``: on top of everything
            continue
        assert src in rank, f"{module}: folder {src!r} is in no layer of LAYERS"
        for target, line, at_top in own_imports(module, path):
            dst = node(target)
            if at_top and dst != src and (dst not in rank or rank[dst] >= rank[src]):
                bad.append(f"{module}:{line} imports {target} ({src} -> {dst})")
    assert not bad, "imports against the layers:\n" + "\n".join(bad)


def test_no_cycle_between_folders():
    edges: dict[str, set] = {}
    for module, path in modules():
        for target, _line, at_top in own_imports(module, path):
            if at_top and node(module) not in ("__init__", "__main__") and node(target) != node(module):
                edges.setdefault(node(module), set()).add(node(target))
    done, stack = set(), []

    def visit(n):
        if n in stack:
            pytest.fail("import cycle between folders: " + " -> ".join(stack[stack.index(n):] + [n]))
        if n in done:
            return
        stack.append(n)
        for m in sorted(edges.get(n, ())):
            visit(m)
        stack.pop()
        done.add(n)

    for n in sorted(edges):
        visit(n)
    assert {"model", "compile", "sampling", "cli"} <= set(edges) | {"model"}  # the walk saw the package


def test_few_imports_of_our_own_inside_functions():
    deferred = [f"{module}:{line} {target}" for module, path in modules()
                for target, line, at_top in own_imports(module, path) if not at_top]
    assert len(deferred) <= MAX_DEFERRED_OWN, "\n".join(deferred)


def test_model_imports_nothing_above_it():
    for module, path in modules():
        if node(module) == "model":
            for target, line, at_top in own_imports(module, path):
                if at_top:
                    assert node(target) in ("model", "errors"), f"{module}:{line} imports {target}"


def test_every_module_imports_on_its_own():
    """Each module imported with none of ours loaded yet (as a fresh interpreter would)."""
    def ours():
        return [m for m in sys.modules if m == "clcsg" or m.startswith("clcsg.")]

    loaded = {name: sys.modules[name] for name in ours()}  # put back afterwards: the other tests
    failures = []                                        # hold these modules' classes
    try:
        for module, _path in modules():
            if module == "clcsg.__main__":
                continue
            for name in ours():
                del sys.modules[name]
            try:
                importlib.import_module(module)
            except Exception as e:  # noqa: BLE001 - reported below with the module's name
                failures.append(f"{module}: {type(e).__name__}: {e}")
    finally:
        for name in ours():
            del sys.modules[name]
        sys.modules.update(loaded)
    assert not failures, "\n".join(failures)


@pytest.mark.parametrize("argv", [["--version"], ["--help"]])
def test_version_and_help_load_neither_numpy_nor_pyopencl(argv):
    code = ("import sys\nfrom clcsg.cli import main\n"
            f"try:\n    main({argv!r})\nexcept SystemExit:\n    pass\n"
            "heavy = sorted({m.split('.')[0] for m in sys.modules} & {'numpy', 'pyopencl', 'PIL'})\n"
            "print('HEAVY', heavy)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert "HEAVY []" in out.stdout, out.stdout


# -- the docs name every module, and every module path they name exists ------------------------
DOCS = ROOT.parent / "docs"
ARCHITECTURE = DOCS / "architecture.md"


def _doc_texts() -> dict[str, str]:
    files = [ROOT.parent / "README.md", *sorted(DOCS.glob("*.md"))]
    return {f.name: f.read_text(encoding="utf-8") for f in files}


def test_architecture_lists_every_module():
    text = ARCHITECTURE.read_text(encoding="utf-8")
    named = set(re.findall(r"`(clcsg/[\w/]+\.py)`", text))
    missing = sorted(str(p.relative_to(ROOT.parent)) for p in ROOT.rglob("*.py")
                     if str(p.relative_to(ROOT.parent)) not in named)
    assert not missing, "modules docs/architecture.md does not name: " + ", ".join(missing)


def test_every_path_and_module_the_docs_name_exists():
    import clcsg

    bad = []
    for name, text in _doc_texts().items():
        for path in re.findall(r"`(clcsg/[\w./-]*)`", text):
            if not (ROOT.parent / path).exists():
                bad.append(f"{name}: {path}")
        for dotted in re.findall(r"\bclcsg\.[a-z_][\w.]*", text):
            parts = dotted.rstrip(".").split(".")
            if parts[1] in clcsg.__all__ or parts[1] == "__version__":
                continue  # a public name such as clcsg.sample
            # the longest prefix that is a module must exist; the rest are its attributes
            k = len(parts)
            while k > 1 and not ((ROOT.parent / pathlib.Path(*parts[:k])).with_suffix(".py").exists()
                                 or (ROOT.parent / pathlib.Path(*parts[:k]) / "__init__.py").exists()):
                k -= 1
            if k == 1:
                bad.append(f"{name}: {dotted}")
    assert not bad, "paths or modules named in the docs that do not exist:\n" + "\n".join(bad)


def test_no_function_over_80_lines():
    long = []
    for _module, path in modules():
        for n in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef)) and n.end_lineno - n.lineno + 1 > 80:
                long.append(f"{path.relative_to(ROOT.parent)}:{n.name} ({n.end_lineno - n.lineno + 1} lines)")
    assert not long, "functions over 80 lines:\n" + "\n".join(long)


def test_no_command_help_loads_pyopencl():
    code = ("import sys\nfrom clcsg.cli import main\n"
            "for cmd in ('devices', 'info', 'sample', 'render', 'batch', 'view'):\n"
            "    try:\n        main([cmd, '--help'])\n    except SystemExit:\n        pass\n"
            "print('PYOPENCL', 'pyopencl' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert "PYOPENCL False" in out.stdout and "usage: clcsg sample" in out.stdout


def test_every_public_name_resolves():
    import clcsg

    missing = [name for name in clcsg.__all__ if getattr(clcsg, name, None) is None]
    assert not missing, missing
    assert {"sample", "render", "write_samples", "load_samples", "to_open3d", "to_trimesh"} <= set(clcsg.__all__)


def test_no_two_modules_share_a_name():
    """A module's name says its one job: the same file name in two folders would be two jobs."""
    seen = {}
    for _module, path in modules():
        if path.name != "__init__.py":
            seen.setdefault(path.name, []).append(str(path.relative_to(ROOT.parent)))
    assert not {k: v for k, v in seen.items() if len(v) > 1}
