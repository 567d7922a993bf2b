"""No class over 300 lines and no function over 100 in the installed packages (``./dev lint`` runs it):
units a reader can hold.

    python test/sizes.py evsync_ros msg_adapters
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

LIMITS = {ast.ClassDef: 300, ast.FunctionDef: 100, ast.AsyncFunctionDef: 100}


def too_long(path: Path) -> list[str]:
    """Each class and function of ``path`` over its limit, as 'file:line name (n lines)'."""
    out = []
    for node in ast.walk(ast.parse(path.read_text(), filename=str(path))):
        limit = LIMITS.get(type(node))
        if limit is not None and isinstance(node, (ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            n = (node.end_lineno or node.lineno) - node.lineno + 1
            if n > limit:
                out.append(f'{path}:{node.lineno} {node.name} ({n} lines, limit {limit})')
    return out


def main(roots: list[str]) -> int:
    found = [line for root in roots for path in sorted(Path(root).rglob('*.py')) for line in too_long(path)]
    print('\n'.join(found), file=sys.stderr) if found else None
    return 1 if found else 0


if __name__ == '__main__':
    raise SystemExit(main(sys.argv[1:]))
