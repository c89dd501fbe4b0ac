"""The code's shape: ``SpringflatEngine.elaborate`` only connects blocks, and no function in ``hdl/`` grows
past what one reader holds in mind."""

import ast
from pathlib import Path

import pytest

HDL = Path(__file__).resolve().parents[1] / "hdl"
ELABORATE_MAX = 149  # SpringflatEngine.elaborate: under 150 lines
FUNCTION_MAX = 200  # any function or method in hdl/


def function_lengths(source: str) -> dict[str, int]:
    """``{qualified name: lines}`` of every function and method in ``source``, decorators and docstring
    included."""
    lengths = {}

    def visit(node, prefix):
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef)):
                start = min([child.lineno] + [d.lineno for d in child.decorator_list])
                lengths[prefix + child.name] = child.end_lineno - start + 1
                visit(child, f"{prefix}{child.name}.")
            elif isinstance(child, ast.ClassDef):
                visit(child, f"{prefix}{child.name}.")
            else:
                visit(child, prefix)

    visit(ast.parse(source), "")
    return lengths


def test_function_lengths_counts_methods_and_nested_functions():
    source = "class A:\n    def f(self):\n        def g():\n            pass\n        return g\n\n\ndef h():\n    pass\n"
    assert function_lengths(source) == {"A.f": 4, "A.f.g": 2, "h": 2}


def test_the_engine_elaborate_only_connects_blocks():
    lengths = function_lengths((HDL / "engine.py").read_text())
    assert lengths["SpringflatEngine.elaborate"] <= ELABORATE_MAX


@pytest.mark.parametrize("path", sorted(HDL.glob("*.py")), ids=lambda p: p.name)
def test_no_function_in_hdl_is_over_the_limit(path):
    long = {name: n for name, n in function_lengths(path.read_text()).items() if n > FUNCTION_MAX}
    assert not long, f"{path.name}: functions over {FUNCTION_MAX} lines: {long}"
