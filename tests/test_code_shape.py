"""The shape of the code itself: every function short enough to read at once."""

from __future__ import annotations

import ast
from pathlib import Path

SOURCE = Path(__file__).resolve().parents[1] / "src" / "lensaudit"

#: Longest function or method, from its ``def`` line to its last line (decorators excluded).
MAX_FUNCTION_LINES = 80


def test_no_function_is_longer_than_80_lines() -> None:
    too_long = []
    for path in sorted(SOURCE.rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
        for node in ast.walk(tree):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                length = node.end_lineno - node.lineno + 1
                if length > MAX_FUNCTION_LINES:
                    where = f"{path.relative_to(SOURCE.parent)}:{node.lineno}"
                    too_long.append(f"{where} {node.name}: {length} lines")
    assert not too_long, (
        f"functions longer than {MAX_FUNCTION_LINES} lines (split them along their steps): "
        + "; ".join(too_long)
    )
