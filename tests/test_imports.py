"""The package keeps ``ials_zoo.lazy_imports``'s rule: only heavy modules are imported inside
functions, and importing the package or its command line loads none of them."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

from ials_zoo.lazy_imports import HEAVY, LAZY_FILES

PACKAGE = Path(__file__).resolve().parents[1] / "ials_zoo"


def _module(path: Path) -> str:
    parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _targets(module: str, is_package: bool, node) -> list[str]:
    """The modules an import statement runs (a package's ``__init__`` and the module itself)."""
    if isinstance(node, ast.Import):
        names = [a.name for a in node.names]
    else:
        base = module.split(".") if is_package else module.split(".")[:-1]
        base = base[:len(base) - node.level + 1] if node.level else []
        prefix = ".".join(base + ([node.module] if node.module else []))
        names = [prefix] + [f"{prefix}.{a.name}" for a in node.names]
    out = []
    for name in names:
        parts = name.split(".")
        out += [".".join(parts[:i]) for i in range(1, len(parts) + 1)]
    return out


def _imports(tree) -> tuple[list, list]:
    """(imports run when the module is imported: at its top, under an ``if`` or ``try`` or in a
    class body; imports inside functions)."""
    top, inner = [], []

    def visit(node, in_function: bool):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.Import, ast.ImportFrom)):
                (inner if in_function else top).append(child)
            visit(child, in_function or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)))

    visit(tree, False)
    return top, inner


def _heavy_modules(files: dict) -> set[str]:
    """Our modules whose top-level imports load a heavy one, directly or through ours."""
    direct = {}
    for module, (path, tree) in files.items():
        top, _ = _imports(tree)
        direct[module] = {t for n in top for t in _targets(module, path.name == "__init__.py", n)}
    heavy = {m for m, ts in direct.items() if any(t.split(".")[0] in HEAVY for t in ts)}
    while True:
        more = {m for m, ts in direct.items() if m not in heavy and ts & heavy}
        if not more:
            return heavy
        heavy |= more


def _package() -> dict:
    return {_module(p): (p, ast.parse(p.read_text())) for p in sorted(PACKAGE.rglob("*.py"))}


def test_only_heavy_modules_are_imported_inside_functions():
    files = _package()
    heavy = _heavy_modules(files)
    light_inside = []
    for module, (path, tree) in files.items():
        if path.name in LAZY_FILES:
            continue
        lines = path.read_text().splitlines()
        _, inner = _imports(tree)
        for node in inner:
            targets = _targets(module, path.name == "__init__.py", node)
            if any(t.split(".")[0] in HEAVY or t in heavy for t in targets) or "# lazy:" in lines[node.lineno - 1]:
                continue
            light_inside.append(f"{path.relative_to(PACKAGE.parent)}:{node.lineno}: {lines[node.lineno - 1].strip()}")
    assert not light_inside, "imported inside a function, though light (ials_zoo/lazy_imports.py):\n" + "\n".join(
        light_inside)


def test_the_rule_sees_a_light_import_inside_a_function(tmp_path, monkeypatch):
    """The check above is not blind: a function importing ``json`` is caught, one importing
    ``torch`` is not."""
    me = sys.modules[__name__]
    pkg = tmp_path / "ials_zoo"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("def f():\n    import json\n\n\ndef g():\n    import torch\n")
    monkeypatch.setattr(me, "PACKAGE", pkg)
    try:
        test_only_heavy_modules_are_imported_inside_functions()
    except AssertionError as e:
        assert "ials_zoo/a.py:2: import json" in str(e) and "torch" not in str(e)
    else:
        raise AssertionError("a light import inside a function went unseen")


def test_the_package_and_its_command_line_load_nothing_heavy():
    code = ("import sys, ials_zoo, ials_zoo.cli, ials_zoo.core.domains; ials_zoo.get_domain('warehouse_v0'); "
            f"print(sorted({{m.split('.')[0] for m in sys.modules}} & set({sorted(HEAVY)!r})))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]", out
