"""The layout keeps its promises: dependencies point one way, only _napari imports the GUI."""

import ast
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parents[1] / "src" / "napari_ssdpc"
GUI = ("napari", "magicgui", "qtpy", "PyQt5", "PyQt6", "PySide2", "PySide6", "superqt", "vispy")
#: layer -> layers it must not import
_TOP = ("analysis", "cli", "_napari", "validation")
FORBIDDEN = {
    "settings": ("physics", "calibration", "reconstruction", "simulation", "io", "pipeline", *_TOP),
    "physics": ("calibration", "reconstruction", "simulation", "io", "pipeline", *_TOP),
    "calibration": ("reconstruction", "simulation", "io", "pipeline", *_TOP),
    "reconstruction": ("simulation", "io", "pipeline", *_TOP),
    "simulation": ("reconstruction", "io", "pipeline", *_TOP),
    # storage only reads and writes: it knows no solver and no frame loop
    "io": ("physics", "calibration", "reconstruction", "simulation", "pipeline", *_TOP),
    # the frame loop runs on measured frames: it knows no simulator and no user interface
    "pipeline": ("simulation", *_TOP),
    # measurements read stored volumes: no solver, no frame loop, no simulator, no user interface
    "analysis": ("calibration", "reconstruction", "simulation", "pipeline", "cli", "_napari", "validation"),
    "cli": ("_napari",),
    "_napari": ("cli",),
    "validation": ("cli", "_napari"),
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


def _declared_api(package: Path) -> tuple[list[str] | None, set[str]]:
    """``__all__`` as the package's ``__init__`` declares it, and the names its imports bind.

    A lazily loaded package declares both in its stub ``__init__.pyi`` (read by lazy_loader at
    run time and by type checkers); an eager one in ``__init__.py``.
    """
    stub = package / "__init__.pyi"
    tree = ast.parse((stub if stub.exists() else package / "__init__.py").read_text())
    declared, bound = None, set()
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(getattr(t, "id", None) == "__all__" for t in node.targets):
            declared = list(ast.literal_eval(node.value))
        elif isinstance(node, ast.ImportFrom):
            bound |= {a.asname or a.name for a in node.names}
    return declared, bound


@pytest.mark.parametrize("package", [PKG, *PACKAGES], ids=lambda p: p.name)
def test_every_package_declares_its_public_api(package):
    """Each package names what it offers (``__all__``, in ``__init__.pyi`` where it loads lazily),
    lists every name it imports, and every name it lists can be had from it."""
    import importlib

    declared, bound = _declared_api(package)
    where = "__init__.pyi" if (package / "__init__.pyi").exists() else "__init__.py"
    assert declared, f"{package.name}/{where} declares no __all__"
    if where == "__init__.pyi":
        differ = sorted(set(declared) ^ bound)
        assert not differ, f"{package.name}/{where}: __all__ and the imports differ in {differ}"
    if package.name == "_napari":
        pytest.importorskip("napari")
    name = "napari_ssdpc" if package == PKG else f"napari_ssdpc.{package.name}"
    mod = importlib.import_module(name)
    assert sorted(getattr(mod, "__all__", [])) == sorted(declared), f"{name}.__all__ is not the declared one"
    missing = []
    for name in declared:
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


def _tree(path: Path):
    return ast.parse(path.read_text())


@pytest.mark.parametrize("path", MODULES, ids=lambda p: str(p.relative_to(PKG)))
def test_imports_name_the_defining_module(path):
    """Absolute imports only (a name's home reads the same everywhere; the ``__init__.pyi`` stubs
    of the lazy packages are the one place for relative ones)."""
    relative = [n.module for n in ast.walk(_tree(path)) if isinstance(n, ast.ImportFrom) and n.level > 0]
    assert not relative, f"{path.relative_to(PKG)} imports relatively: {relative}"


@pytest.mark.parametrize("path", [p for p in MODULES if p.name != "__init__.py"], ids=lambda p: str(p.relative_to(PKG)))
def test_no_module_re_exports_what_it_imports(path):
    """A module's ``__all__`` lists only what it defines: one import path per public name."""
    tree = _tree(path)
    defined, declared = set(), []
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            defined.add(node.name)
        elif isinstance(node, ast.Assign):
            for t in node.targets:
                if isinstance(t, ast.Name) and t.id == "__all__":
                    declared = list(ast.literal_eval(node.value))
                defined |= {n.id for n in ast.walk(t) if isinstance(n, ast.Name)}
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            defined.add(node.target.id)
    foreign = sorted(set(declared) - defined)
    assert not foreign, f"{path.relative_to(PKG)} re-exports {foreign}: import them from their own module"


def _calls(path: Path, names) -> list[str]:
    found = []
    for node in ast.walk(_tree(path)):
        if isinstance(node, ast.Call):
            f = node.func
            name = f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", "")
            if name in names:
                found.append(f"{name} (line {node.lineno})")
    return found


@pytest.mark.parametrize("layer", ["cli", "_napari"])
def test_the_user_interfaces_run_frames_through_the_pipeline(layer):
    """The CLI and napari reconstruct through :class:`napari_ssdpc.pipeline.run.Pipeline`: neither
    builds a Reconstructor, reconstructs a frame or writes a series store itself."""
    direct = {"Reconstructor", "reconstruct", "write_frame", "open_store", "process_frame"}
    for path in sorted((PKG / layer).rglob("*.py")):
        found = _calls(path, direct)
        assert not found, f"{path.relative_to(PKG)} calls {found}: run frames through pipeline.run.Pipeline"


def test_every_phase_method_is_registered_and_implements_the_interface():
    """The settings' method choices, the registry and the modules agree; every method is a
    PhaseMethod whose name is its key."""
    from napari_ssdpc.reconstruction.methods import METHODS, method_class
    from napari_ssdpc.reconstruction.methods.base import PhaseMethod
    from napari_ssdpc.settings.reconstruction import PHASE_METHODS, ReconstructionSettings

    assert tuple(METHODS) == PHASE_METHODS
    for name in METHODS:
        cls = method_class(name)
        assert issubclass(cls, PhaseMethod) and cls.name == name
        assert name in ReconstructionSettings.model_fields, f"no settings section '{name}'"
    modules = {p.stem for p in (PKG / "reconstruction" / "methods").glob("*.py")} - {"__init__", "base"}
    assert modules == {e.module.rsplit(".", 1)[1] for e in METHODS.values()}, "a method module is not registered"


@pytest.mark.parametrize("path", [p for p in MODULES if p.name != "backend.py"], ids=lambda p: str(p.relative_to(PKG)))
def test_fourier_transforms_go_through_the_backend(path):
    """One FFT entry (``napari_ssdpc.backend``): a transform called straight from SciPy or NumPy
    would run on one core or not on the GPU; helpers such as ``fftfreq`` and ``next_fast_len`` are fine."""
    import re

    direct = re.findall(r"\b(?:sfft|scipy\.fft|np\.fft|numpy\.fft)\.(i?r?fftn?2?)\(", path.read_text())
    assert not direct, (
        f"{path.relative_to(PKG)} calls {sorted(set(direct))} directly; use a Backend (bk.fft2, cpu().rfft2)"
    )


def _module_name(path: Path) -> str:
    rel = path.relative_to(PKG.parent).with_suffix("")
    return ".".join(rel.parts[:-1] if rel.name == "__init__" else rel.parts)


def test_no_two_modules_import_each_other():
    """No import circle between our modules, counting the imports inside functions too: a circle
    means two modules share a concern that belongs in a third."""
    names = {_module_name(p): p for p in MODULES}
    graph = {}
    for name, path in names.items():
        if path.name == "__init__.py":
            continue
        graph[name] = {m for m in _imports(path) if m in names and not names[m].name == "__init__.py" and m != name}
    # Tarjan-free: a circle exists where a module reaches itself
    circles = set()
    for start in graph:
        seen, stack = set(), [(start, (start,))]
        while stack:
            node, trail = stack.pop()
            for nxt in graph.get(node, ()):
                if nxt == start:
                    circles.add(tuple(sorted(trail)))
                elif nxt not in seen:
                    seen.add(nxt)
                    stack.append((nxt, (*trail, nxt)))
    assert not circles, f"import circles: {sorted(circles)}"
