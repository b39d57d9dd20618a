"""napari sample data: simulated frames, generated on demand and cached (no downloads)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from . import __version__


def cache_dir() -> Path:
    root = os.environ.get("NAPARI_SSDPC_CACHE") or Path.home() / ".cache" / "napari-ssdpc"
    path = Path(root) / __version__
    path.mkdir(parents=True, exist_ok=True)
    return path


def _cached(name: str, make) -> np.ndarray:
    import tifffile

    from .core.io import write_tiff

    path = cache_dir() / f"{name}.tif"
    if path.is_file():
        return tifffile.imread(path)
    data = make()
    write_tiff(path, data)
    return data


def pmma_bead_sample():
    """The paper's PMMA bead (13 µm, n 1.49 in 1.518) and its flat frame, paper optics."""
    from .core import simulate as sim
    from .core.optics import Optics

    optics = Optics.paper()
    frame = _cached("pmma_bead", lambda: sim.simulate(sim.pmma_bead(), optics, rng=np.random.default_rng(0)).frame)
    flat = _cached("pmma_bead_flat", lambda: sim.flat_frame(optics, rng=np.random.default_rng(1)))
    meta = {"optics": optics.to_dict(), "source": "napari-ssdpc simulator"}
    return [
        (frame, {"name": "PMMA bead (raw light field)", "metadata": meta}, "image"),
        (flat, {"name": "PMMA bead flat frame", "metadata": meta, "visible": False}, "image"),
    ]
