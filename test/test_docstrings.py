"""The public API is documented as numpy-style docstrings: a one-line summary, and Parameters and
Returns sections where a function takes or gives values (as python-control and scikit-learn check)."""

import ast
import re
from pathlib import Path

import ship_ident

PACKAGE = Path(ship_ident.__file__).parent
# The numeric core's modules whose API the rest of the package builds on.
API_MODULES = ("model.structure", "model.effects", "model.dataset", "diagnosis.diagnose", "estimators")


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def imported_names() -> dict:
    """Module -> names other modules of the package import from it (``from .x import name``)."""
    found = {}
    for path in PACKAGE.rglob("*.py"):
        me = module_name(path)
        package = me.split(".") if path.name == "__init__.py" else me.split(".")[:-1]
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.level:
                base = package[: len(package) - node.level + 1]
                target = ".".join([*base, *(node.module.split(".") if node.module else [])])
                if target != me:
                    found.setdefault(target, set()).update(alias.name for alias in node.names)
    return found


def public_api() -> list:
    """(module, definition) of every public function and class that other modules use."""
    used = imported_names()
    api = []
    for path in sorted(PACKAGE.rglob("*.py")):
        module = module_name(path)
        if not any(module == m or module.startswith(m + ".") for m in API_MODULES):
            continue
        for node in ast.parse(path.read_text()).body:
            if isinstance(node, (ast.FunctionDef, ast.ClassDef)) and not node.name.startswith("_"):
                if node.name in used.get(module, ()):
                    api.append((module, node))
    return api


def problems(node) -> list[str]:
    """What a definition's docstring lacks."""
    doc = ast.get_docstring(node)
    if not doc:
        return ["no docstring"]
    lines = doc.splitlines()
    out = [] if len(lines) == 1 or not lines[1].strip() else ["no one-line summary"]
    if isinstance(node, ast.FunctionDef):
        arguments = [a.arg for a in node.args.args + node.args.kwonlyargs if a.arg not in ("self", "cls")]
        if arguments and not re.search(r"^Parameters\n-{3,}$", doc, re.M):
            out.append("no Parameters section")
        returns = node.returns
        gives = not (returns is None or (isinstance(returns, ast.Constant) and returns.value is None))
        if gives and not re.search(r"^Returns\n-{3,}$", doc, re.M):
            out.append("no Returns section")
    return out


def test_the_check_finds_the_api_and_what_a_docstring_lacks():
    names = {f"{module}.{node.name}" for module, node in public_api()}
    assert {
        "model.structure.Structure",
        "model.dataset.cut_segments",
        "estimators.make_estimator",
        "diagnosis.diagnose.diagnose",
    } <= names
    bare = ast.parse('def f(x) -> int:\n    """Sum\n    of x."""\n').body[0]
    assert problems(bare) == ["no one-line summary", "no Parameters section", "no Returns section"]


def test_the_public_api_has_numpy_style_docstrings():
    missing = [f"{module}.{node.name}: {', '.join(p)}" for module, node in public_api() if (p := problems(node))]
    assert not missing, "docstrings to complete:\n" + "\n".join(missing)
