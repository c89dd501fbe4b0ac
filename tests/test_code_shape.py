"""The code's shape: ``SpringflatEngine.elaborate`` only connects blocks, and no function in ``hdl/`` grows
past what one reader holds in mind."""

import ast
import io
import re
import tokenize
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


#: A commit hash (7 to 40 hex digits with a letter and a digit) or a clock figure in MHz.
COMMIT_HASH = re.compile(r"\b(?=[0-9a-f]*[a-f])(?=[0-9a-f]*[0-9])[0-9a-f]{7,40}\b")
MHZ = re.compile(r"\d(\.\d+)?\s*MHz")
#: Files whose comments name the board's real clocks (the oscillator, the PLL), not a past result.
CLOCK_FILES = {"board.py", "uart_bridge.py"}


def comments_and_docstrings(source: str) -> list[tuple[int, str]]:
    """``(line, text)`` of every comment and docstring in ``source``."""
    found = [(tok.start[0], tok.string) for tok in tokenize.generate_tokens(io.StringIO(source).readline)
             if tok.type == tokenize.COMMENT]
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and node.body:
            first = node.body[0]
            if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant) \
                    and isinstance(first.value.value, str):
                found.append((first.lineno, first.value.value))
    return found


def history_in(source: str, *, clocks_allowed: bool = False) -> list[str]:
    """The comments and docstrings of ``source`` that cite a commit hash or (unless ``clocks_allowed``)
    a figure in MHz: the design's history, which lives in git and the results file."""
    return [f"line {line}: {text.strip()[:100]}" for line, text in comments_and_docstrings(source)
            if COMMIT_HASH.search(text) or (not clocks_allowed and MHZ.search(text))]


def test_history_in_finds_hashes_and_mhz_but_not_words():
    source = '"""A module."""\n# was the critical path at 4338217, 119.3 MHz\nx = 1  # deadbeef faded\n' \
             'def f():\n    """eae9e83\'s path."""\n'
    assert [h.split(":")[0] for h in history_in(source)] == ["line 2", "line 5"]
    assert history_in('"""The 25 MHz oscillator."""\n', clocks_allowed=True) == []


@pytest.mark.parametrize("path", sorted(HDL.glob("*.py")), ids=lambda p: p.name)
def test_no_history_in_hdl_comments(path):
    found = history_in(path.read_text(), clocks_allowed=path.name in CLOCK_FILES)
    assert not found, f"{path.name}: " + "; ".join(found)
