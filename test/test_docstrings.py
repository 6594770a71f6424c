"""The public API is documented as numpy-style docstrings: a one-line summary, and Parameters and
Returns sections where a function or method takes or gives values (as python-control and scikit-learn
check), in the numeric core's packages."""

import ast
import re
from pathlib import Path

import ship_ident

PACKAGE = Path(ship_ident.__file__).parent
# The numeric core, whose API the node, the commands and the benches build on.
API_PACKAGES = ("model", "estimators", "online", "diagnosis")
PROPERTIES = ("property", "cached_property")  # read as attributes: a summary says what they hold


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


def in_core(module: str) -> bool:
    return any(module == p or module.startswith(p + ".") for p in API_PACKAGES)


def public_api() -> list:
    """(module, qualified name, definition) of every public function and class of the core that other
    modules use, and of the public methods and properties of those classes."""
    used = imported_names()
    api = []
    for path in sorted(PACKAGE.rglob("*.py")):
        module = module_name(path)
        if not in_core(module):
            continue
        for node in ast.parse(path.read_text()).body:
            if isinstance(node, (ast.FunctionDef, ast.ClassDef)) and not node.name.startswith("_"):
                if node.name in used.get(module, ()):
                    api.append((module, node.name, node))
                    if isinstance(node, ast.ClassDef):
                        api.extend(
                            (module, f"{node.name}.{method.name}", method)
                            for method in node.body
                            if isinstance(method, ast.FunctionDef) and not method.name.startswith("_")
                        )
    return api


def gives_a_value(node: ast.FunctionDef) -> bool:
    """Whether a function returns a value: annotated so, or a ``return x`` in its own body (not in
    functions defined inside it)."""
    if node.returns is not None:
        return not (isinstance(node.returns, ast.Constant) and node.returns.value is None)
    own = list(ast.iter_child_nodes(node))
    while own:
        child = own.pop()
        if isinstance(child, ast.Return) and child.value is not None:
            return not (isinstance(child.value, ast.Constant) and child.value.value is None)
        if not isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda, ast.ClassDef)):
            own.extend(ast.iter_child_nodes(child))
    return False


def problems(node) -> list[str]:
    """What a definition's docstring lacks (a property needs only its summary)."""
    doc = ast.get_docstring(node)
    if not doc:
        return ["no docstring"]
    lines = doc.splitlines()
    out = [] if len(lines) == 1 or not lines[1].strip() else ["no one-line summary"]
    if isinstance(node, ast.FunctionDef):
        if any(getattr(d, "id", getattr(d, "attr", None)) in PROPERTIES for d in node.decorator_list):
            return out
        arguments = [a.arg for a in node.args.args + node.args.kwonlyargs if a.arg not in ("self", "cls")]
        if arguments and not re.search(r"^Parameters\n-{3,}$", doc, re.M):
            out.append("no Parameters section")
        if gives_a_value(node) and not re.search(r"^(Returns|Yields)\n-{3,}$", doc, re.M):
            out.append("no Returns section")
    return out


def lacking() -> dict:
    """'module.name' -> what its docstring lacks, over the public API."""
    return {f"{module}.{name}": p for module, name, node in public_api() if (p := problems(node))}


def test_the_check_finds_the_api_and_what_a_docstring_lacks():
    names = {f"{module}.{name}" for module, name, _ in public_api()}
    assert {
        "model.structure.Structure",
        "model.structure.Structure.simulate",
        "model.dataset.cut_segments",
        "estimators.make_estimator",
        "diagnosis.diagnose.diagnose",
        "online.identifier.OnlineIdentifier.refit",
        "online.trust.TrustPolicy.plausibility",
    } <= names
    assert not any(name.split(".")[-1].startswith("_") for name in names)
    bare = ast.parse('def f(x):\n    """Sum\n    of x."""\n    return x\n').body[0]
    assert problems(bare) == ["no one-line summary", "no Parameters section", "no Returns section"]
    inner = ast.parse('def f():\n    """Nothing."""\n    def g():\n        return 1\n    return None\n').body[0]
    assert problems(inner) == []
    attribute = ast.parse('@cached_property\ndef f(self) -> int:\n    """The value (s)."""\n    return 1\n').body[0]
    assert problems(attribute) == []


def test_the_public_api_has_numpy_style_docstrings():
    missing = [f"{name}: {', '.join(p)}" for name, p in lacking().items()]
    assert not missing, "docstrings to complete:\n" + "\n".join(missing)
