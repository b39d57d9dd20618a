"""The layout keeps its promises: dependencies point one way, only _napari imports the GUI."""

import ast
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parents[1] / "src" / "napari_ssdpc"
GUI = ("napari", "magicgui", "qtpy", "PyQt5", "PyQt6", "PySide2", "PySide6", "superqt", "vispy")
#: layer -> layers it must not import
FORBIDDEN = {
    "settings": ("physics", "calibration", "reconstruction", "simulation", "io", "cli", "_napari", "validation"),
    "physics": ("calibration", "reconstruction", "simulation", "io", "cli", "_napari", "validation"),
    "calibration": ("reconstruction", "simulation", "io", "cli", "_napari", "validation"),
    "reconstruction": ("simulation", "io", "cli", "_napari", "validation"),
    "simulation": ("reconstruction", "io", "cli", "_napari", "validation"),
    "io": ("cli", "_napari", "validation"),
}


def _imports(path: Path) -> set[str]:
    names = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            names |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
    return names


MODULES = sorted(p for p in PKG.rglob("*.py"))


@pytest.mark.parametrize("path", MODULES, ids=lambda p: str(p.relative_to(PKG)))
def test_layers_point_one_way_and_gui_stays_in_napari(path):
    rel = path.relative_to(PKG)
    layer = rel.parts[0] if len(rel.parts) > 1 else None
    imported = _imports(path)
    if layer != "_napari":
        gui = sorted(m for m in imported if m.split(".")[0] in GUI)
        assert not gui, f"{rel} imports {gui}: GUI code belongs in _napari/"
    for bad in FORBIDDEN.get(layer, ()):
        upward = sorted(m for m in imported if m.startswith(f"napari_ssdpc.{bad}"))
        assert not upward, f"{rel} ({layer}) imports {upward}: dependencies point one way"


def test_nothing_cites_files_outside_the_repository():
    root = PKG.parents[1]
    words = ("DESIGN.md", "shared/paper", "STYLE.md", "../shared")
    for path in [*root.joinpath("src").rglob("*.py"), *root.joinpath("docs").rglob("*.md"), root / "README.md"]:
        text = path.read_text(encoding="utf-8")
        found = [w for w in words if w in text]
        assert not found, f"{path.relative_to(root)} cites {found}"


def test_the_build_can_read_the_version():
    """hatchling reads ``__version__`` from _version.py with a regex: it must be a plain literal."""
    import re
    import tomllib

    root = PKG.parents[1]
    config = tomllib.loads((root / "pyproject.toml").read_text())
    source = (root / config["tool"]["hatch"]["version"]["path"]).read_text()
    found = re.search(r"""^__version__\s*=\s*["']([^"']+)["']""", source, re.MULTILINE)
    assert found is not None, "_version.py must hold __version__ = '<x.y.z>' as a literal"
    assert re.fullmatch(r"\d+\.\d+\.\d+", found.group(1))


def _public_definitions(path: Path):
    """(name, node) of every public function, class and public method of a module."""
    for node in ast.parse(path.read_text()).body:
        if isinstance(node, (ast.FunctionDef, ast.ClassDef)) and not node.name.startswith("_"):
            yield node.name, node
            if isinstance(node, ast.ClassDef):
                for item in node.body:
                    if isinstance(item, ast.FunctionDef) and not item.name.startswith("_"):
                        yield f"{node.name}.{item.name}", item


@pytest.mark.parametrize("path", MODULES, ids=lambda p: str(p.relative_to(PKG)))
def test_public_definitions_have_numpydoc_docstrings(path):
    """Every public function, class and method says what it does; one that takes arguments has a
    numpydoc Parameters section (with shapes and units where they apply)."""
    missing, no_parameters = [], []
    for name, node in _public_definitions(path):
        doc = ast.get_docstring(node)
        if not doc:
            missing.append(name)
            continue
        if isinstance(node, ast.FunctionDef):
            args = [a.arg for a in node.args.args + node.args.kwonlyargs if a.arg not in ("self", "cls")]
            decorators = {getattr(d, "id", getattr(d, "attr", "")) for d in node.decorator_list}
            if args and "property" not in decorators and "Parameters" not in doc:
                no_parameters.append(name)
    assert not missing, f"no docstring: {', '.join(missing)}"
    assert not no_parameters, f"no Parameters section: {', '.join(no_parameters)}"


PACKAGES = sorted(p.parent for p in PKG.glob("*/__init__.py"))


@pytest.mark.parametrize("package", PACKAGES, ids=lambda p: p.name)
def test_every_package_declares_its_public_api(package):
    """Each package names what it offers (``__all__``), and every name it lists can be had from it."""
    import importlib

    if package.name == "_napari":
        pytest.importorskip("napari")
    mod = importlib.import_module(f"napari_ssdpc.{package.name}")
    names = getattr(mod, "__all__", None)
    assert names, f"{package.name}/__init__.py has no __all__"
    missing = []
    for name in names:
        try:
            getattr(mod, name) if hasattr(mod, name) else importlib.import_module(f"{mod.__name__}.{name}")
        except (AttributeError, ImportError):
            missing.append(name)
    assert not missing, f"{package.name}: __all__ lists {missing}, which it does not provide"


#: The most lines of code (docstrings, comments and blank lines aside) one module may hold.
MAX_CODE_LINES = 400


def _code_lines(path: Path) -> int:
    import io
    import tokenize

    src = path.read_text()
    docs = set()
    for node in ast.walk(ast.parse(src)):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and node.body:
            first = node.body[0]
            if isinstance(first, ast.Expr) and isinstance(getattr(first, "value", None), ast.Constant):
                docs.update(range(first.lineno, first.end_lineno + 1))
    skip = (tokenize.COMMENT, tokenize.NL, tokenize.NEWLINE, tokenize.INDENT, tokenize.DEDENT, tokenize.ENDMARKER)
    lines = set()
    for tok in tokenize.generate_tokens(io.StringIO(src).readline):
        if tok.type not in skip:
            lines.update(n for n in range(tok.start[0], tok.end[0] + 1) if n not in docs)
    return len(lines)


@pytest.mark.parametrize("path", MODULES, ids=lambda p: str(p.relative_to(PKG)))
def test_modules_stay_small(path):
    """One concern per module: none holds more than MAX_CODE_LINES lines of code."""
    n = _code_lines(path)
    assert n <= MAX_CODE_LINES, f"{path.name}: {n} lines of code (at most {MAX_CODE_LINES}); split it by concern"
