"""The code stays readable: no function a reader cannot hold at once."""

import ast
from pathlib import Path

import ship_ident

PACKAGE = Path(ship_ident.__file__).parent
# Lines of code of a function, its docstring not counted (documentation is not what a reader must
# hold); compiled kernels (numba @njit) excepted: one loop each, kept whole for speed.
MAX_FUNCTION_LINES = 150


def compiled(node: ast.AST) -> bool:
    """Whether a function is a numba kernel (decorated with njit or jit, called or not)."""
    for decorator in getattr(node, "decorator_list", []):
        target = decorator.func if isinstance(decorator, ast.Call) else decorator
        name = target.attr if isinstance(target, ast.Attribute) else getattr(target, "id", "")
        if name in ("njit", "jit"):
            return True
    return False


def function_lengths() -> dict:
    """Lines of every function and method of the package without its docstring, by 'path:line:name'."""
    lengths = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and not compiled(node):
                key = f"{path.relative_to(PACKAGE)}:{node.lineno}:{node.name}"
                lines = node.end_lineno - node.lineno + 1
                first = node.body[0]
                if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant):
                    lines -= first.end_lineno - first.lineno + 1  # the docstring
                lengths[key] = lines
    return lengths


def test_the_length_rule_sees_functions_and_spares_kernels():
    lengths = function_lengths()
    assert any(key.endswith(":_refine") for key in lengths)
    assert not any(key.endswith(":simulate_kernel") for key in lengths)  # integrate's @njit kernel


def test_no_function_is_longer_than_a_reader_can_hold():
    long = {key: n for key, n in function_lengths().items() if n > MAX_FUNCTION_LINES}
    assert not long, f"functions over {MAX_FUNCTION_LINES} lines: {long}"
