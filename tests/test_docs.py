"""The Python examples in the README and docs/ name modules and functions that exist."""

from __future__ import annotations

import ast
import importlib
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
_BLOCK = re.compile(r"```python\n(.*?)```", re.S)


def _imports(page: Path):
    for block in _BLOCK.findall(page.read_text(encoding="utf-8")):
        for node in ast.walk(ast.parse(block)):
            if isinstance(node, ast.ImportFrom) and node.module and node.module.startswith("napari_ssdpc"):
                for alias in node.names:
                    yield node.module, alias.name
            elif isinstance(node, ast.Import):
                for alias in node.names:
                    if alias.name.startswith("napari_ssdpc"):
                        yield alias.name, None


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_python_examples_import_what_exists(page):
    for module, name in _imports(page):
        mod = importlib.import_module(module)
        if name is not None:
            assert hasattr(mod, name) or importlib.util.find_spec(f"{module}.{name}"), f"{page.name}: {module}.{name}"
