"""The public API: what a user imports from ``napari_ssdpc`` and its packages, loaded on first use."""

import subprocess
import sys
import textwrap

import pytest

#: Packages that load their public names lazily (``__init__.pyi``).
LAZY = [f"napari_ssdpc{p}" for p in ("", ".analysis", ".calibration", ".io", ".reconstruction", ".simulation")]
#: Modules that a light import must not load.
HEAVY = ("numpy", "scipy", "pydantic", "tifffile", "zarr", "dask", "matplotlib", "napari")


def _run(code: str) -> str:
    """Run ``code`` in a fresh interpreter (nothing of ours imported yet); its stdout."""
    done = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    return done.stdout


@pytest.mark.parametrize("package", ["napari_ssdpc", "napari_ssdpc.calibration", "napari_ssdpc.io"])
def test_importing_a_package_loads_nothing_heavy(package):
    """napari imports ``napari_ssdpc`` to read the manifest: that must not load numpy and the rest."""
    out = _run(f"import sys, {package}; print(sorted(m for m in {HEAVY!r} if m in sys.modules))")
    assert out.strip() == "[]", f"import {package} loads {out.strip()}"


def test_the_user_facing_names_come_from_the_top_level():
    from napari_ssdpc import (
        Calibration,
        Optics,
        ReconstructionSettings,
        Reconstructor,
        Result,
        RunConfig,
        SsdpcError,
        SsdpcWarning,
        calibrate,
        extract_views,
        flat_frame,
        pmma_bead,
        read_frame,
        simulate,
        white_frame,
    )
    from napari_ssdpc.calibration.measure import calibrate as defined
    from napari_ssdpc.io.frames import read_frame as read
    from napari_ssdpc.settings.optics import Optics as Defined

    assert calibrate is defined and read_frame is read and Optics is Defined
    assert all(callable(f) for f in (extract_views, flat_frame, pmma_bead, simulate, white_frame))
    assert issubclass(SsdpcError, ValueError) and issubclass(SsdpcWarning, UserWarning)
    for cls in (Calibration, ReconstructionSettings, Reconstructor, Result, RunConfig):
        assert isinstance(cls, type)


@pytest.mark.parametrize("package", LAZY)
def test_a_public_name_keeps_its_meaning_after_its_modules_load(package):
    """Importing a package's submodules (as the pipeline and the tests do) never turns a public
    name into a module: ``from napari_ssdpc.calibration import calibrate`` is the function before
    and after ``napari_ssdpc.calibration.<module>`` is imported."""
    out = _run(
        f"""
        import importlib, pkgutil, types
        import {package} as pkg
        names = [n for n in pkg.__all__ if not n.startswith("__")]
        before = {{n: getattr(pkg, n) for n in names}}
        for info in pkgutil.iter_modules(pkg.__path__):
            if not info.ispkg:
                importlib.import_module(f"{package}.{{info.name}}")
        for n in names:
            ns = {{}}
            exec(f"from {package} import {{n}} as again", ns)
            if ns["again"] is not before[n] or isinstance(before[n], types.ModuleType):
                print(n)
        """
    )
    assert not out.split(), f"{package}: {out.split()} changed meaning once their modules were imported"
