"""The Python examples of README.md and docs/*.md as files, for the type checkers (tests/test_types.py).

Every fenced ``python`` block becomes one module, named after its page and position
(``readme_1.py``, ``docs_getting_started_2.py``), so that mypy and pyright check it as a user's
file would be checked. A block that is not a complete program (a fragment continuing the previous
one, say) starts with the line ``# snippet: fragment`` and is left out.

``python tests/_snippets.py`` writes them to build/doc-snippets, the folder that pyproject's
``[tool.pyright]`` and ``[tool.mypy]`` name beside src/, so that a plain ``pyright`` or ``mypy``
in the checkout checks the examples too.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: The folder the configuration names (build/ is not committed).
DEFAULT_DEST = ROOT / "build" / "doc-snippets"
FRAGMENT = "# snippet: fragment"
_FENCE = re.compile(r"^```python[ \t]*\n(.*?)^```", re.S | re.M)


def pages() -> list[Path]:
    """README.md and the documentation's top-level pages, in a fixed order."""
    return [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def blocks(page: Path) -> list[str]:
    """The page's ``python`` blocks, fragments included."""
    return [m.group(1) for m in _FENCE.finditer(page.read_text(encoding="utf-8"))]


def is_fragment(code: str) -> bool:
    return code.lstrip().startswith(FRAGMENT)


def extract(dest: Path) -> dict[Path, tuple[Path, int]]:
    """Write every complete block to ``dest`` (emptied of earlier snippets first); returns
    {file: (page, index of the block on its page, from 1)}."""
    dest.mkdir(parents=True, exist_ok=True)
    for old in dest.glob("*.py"):
        old.unlink()
    out: dict[Path, tuple[Path, int]] = {}
    for page in pages():
        stem = "readme" if page.name == "README.md" else "docs_" + page.stem
        stem = re.sub(r"\W", "_", stem.lower())
        for i, code in enumerate(blocks(page), start=1):
            if is_fragment(code):
                continue
            f = dest / f"{stem}_{i}.py"
            f.write_text(code, encoding="utf-8")
            out[f] = (page, i)
    return out


if __name__ == "__main__":
    target = Path(sys.argv[1]) if len(sys.argv) > 1 else DEFAULT_DEST
    written = extract(target)
    print(f"{len(written)} snippets in {target}")
