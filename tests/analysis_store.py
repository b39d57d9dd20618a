"""Results on disk for the measurement tests, written by the product's own sinks: the phantoms'
Δn blurred to the default resolution with noise of 1/50 of the cytoplasm's Δn."""

from types import SimpleNamespace

import numpy as np
from scipy import ndimage

from napari_ssdpc._version import SOFTWARE
from napari_ssdpc.analysis.objects import DEFAULT_RULE, FWHM_PER_SIGMA
from napari_ssdpc.pipeline.sinks import OutputGrid, ZarrSink
from napari_ssdpc.reconstruction.frame_result import Result
from napari_ssdpc.settings.config import RunConfig
from napari_ssdpc.settings.optics import Optics
from napari_ssdpc.simulation import moving

DX = 0.8456
Z = np.arange(-30.0, 31.0, 1.0)
Y = X = (np.arange(128) - 63.5) * DX
ALPHA = 0.2  # µm³/pg, as the result was "reconstructed" with (not the default 0.19)
N_MEDIUM = 1.33


def run_settings():
    """(reconstruction settings, optics) as dicts, the way a result stores them."""
    config = RunConfig.of(Optics.paper().replace(medium_index=N_MEDIUM), z_min_um=-30, z_max_um=30, dz_um=1)
    return {**config.reconstruction.to_dict(), "refraction_increment_um3_pg": ALPHA}, config.optics.to_dict()


def result(phantom, seed):
    """A Result holding the phantom's Δn blurred to the default resolution, with noise of 1/50 of its Δn."""
    dn = phantom.volume(Z, Y, X).real
    fz, fxy = DEFAULT_RULE.resolution_um
    s = (fz / FWHM_PER_SIGMA, fxy / FWHM_PER_SIGMA / DX, fxy / FWHM_PER_SIGMA / DX)
    dn = ndimage.gaussian_filter(dn, s) + np.random.default_rng(seed).normal(0, 0.03 / 50, dn.shape)
    dn = dn.astype(np.float32)
    stored, _ = run_settings()
    return Result(N_MEDIUM + dn, dn, dn, None, {}, {}, Z, Y, X, settings=stored)


def truth(phantom):
    """(∫Δn dV µm³, Δn-weighted centroid (x, y, z) µm) of a phantom in water, analytic."""
    parts = phantom.parts(N_MEDIUM)
    weights = [p.dn.real * 4 / 3 * np.pi * np.prod(p.semi_axes_um) for p in parts]
    return sum(weights), np.average([p.center_um for p in parts], axis=0, weights=weights)


def source(n):
    """A finished frame source of ``n`` frames, as the sinks see one."""
    ident = {"path": "array", "size": None, "mtime_ns": None, "frames": n, "sha256": "0" * 64}
    return SimpleNamespace(
        available=lambda: n, finished=lambda: True, identity=lambda: ident, frame_shape=(8, 8), name="raw.tif"
    )


def write_moving_store(out):
    """A 6-frame store of the moving sample written by ZarrSink, frames 0-4 complete (5 never written)."""
    series = moving.moving_sample(20)[:6]
    stored, optics = run_settings()
    sink = ZarrSink(out, meta={"software": SOFTWARE, "optics": optics})
    job = SimpleNamespace(result_key="k", config=SimpleNamespace(outputs=SimpleNamespace(store_digits=None)))
    sink.open(job, OutputGrid(Z, Y, X, stored), source(6))
    for t, p in enumerate(series[:5]):
        sink.write(t, result(p, t))
    sink.close()
    return out
