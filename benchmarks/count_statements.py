"""Count the library's statements on the syntax tree (docstrings excluded; comments and joined
lines do not count), per top-level package and in total.

Usage: ``python benchmarks/count_statements.py [src/calstudy]``.
"""

from __future__ import annotations

import ast
import sys
from collections import Counter
from pathlib import Path


def statements(source: str) -> int:
    """Statements of one module's source, docstrings (bare string expressions) excluded."""
    return sum(
        1
        for node in ast.walk(ast.parse(source))
        if isinstance(node, ast.stmt)
        and not (
            isinstance(node, ast.Expr)
            and isinstance(node.value, ast.Constant)
            and isinstance(node.value.value, str)
        )
    )


def main(root: Path) -> None:
    counts: Counter[str] = Counter()
    for path in sorted(root.rglob("*.py")):
        parts = path.relative_to(root).parts
        counts[parts[0] if len(parts) > 1 else "."] += statements(path.read_text())
    for package, n in sorted(counts.items()):
        print(f"{package:12s} {n:6d}")
    print(f"{'total':12s} {sum(counts.values()):6d}")


if __name__ == "__main__":
    main(Path(sys.argv[1] if len(sys.argv) > 1 else "src/calstudy"))
