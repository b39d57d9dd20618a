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


def test_the_architecture_examples_run(synthetic_series):
    """docs/architecture.md's worked examples (a new phase method, a new frame source) run as printed,
    on a frame of the paper's optics, and do what they say."""
    optics, calibration, flat, frames, _ = synthetic_series
    ns = {"optics": optics, "calibration": calibration, "flat": flat, "frames": frames[:2]}
    for block in _BLOCK.findall((ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")):
        exec(compile(block, "docs/architecture.md", "exec"), ns)
    result = ns["result"]
    assert result.settings["method"] == "signed" and float(result.delta_n.min()) >= 0.0
    assert 0.0 < result.settings["clipped_fraction"] < 1.0
    assert ns["report"].written == 2 and sorted(ns["sink"].frames) == [0, 1]


def test_the_method_table_lists_every_registered_method():
    from napari_ssdpc.reconstruction.methods import METHODS

    text = (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")
    for name, entry in METHODS.items():
        path = entry.module.replace("napari_ssdpc.", "").replace(".", "/") + ".py"
        assert f"| `{name}`" in text and path in text, f"docs/architecture.md: no row for the method {name}"


def test_the_readme_run_configuration_reads(tmp_path):
    """The README's run.yaml is complete as printed: it reads, and its values arrive."""
    from napari_ssdpc.settings.config import RunConfig
    from napari_ssdpc.settings.optics import Optics

    block = re.search(r"```yaml\n(# run\.yaml.*?)```", (ROOT / "README.md").read_text(encoding="utf-8"), re.S)
    assert block is not None, "README.md: no run.yaml example"
    (tmp_path / "run.yaml").write_text(block.group(1), encoding="utf-8")
    calibrated = Optics.paper().replace(condenser_na=0.3)
    cfg = RunConfig.from_yaml(tmp_path / "run.yaml", default_optics=calibrated)
    assert cfg.optics == calibrated and cfg.reconstruction.z_min_um == -60 and cfg.reconstruction.tv.iterations == 60
    assert cfg.outputs.save == ("opd_nm", "dry_mass")
