"""Validation on simulated phantoms: simulate, calibrate, reconstruct (measured against the truth
by :mod:`napari_ssdpc.validation.truth`).

Used by the slow tests and by ``docs/make_validation.py``; also useful to plan an experiment
(which condenser NA, which z range) before going to the microscope.
"""

from __future__ import annotations

import json
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from napari_ssdpc.calibration import calibrate
from napari_ssdpc.errors import SsdpcWarning
from napari_ssdpc.files import atomic_write
from napari_ssdpc.physics.lattice import Grid
from napari_ssdpc.reconstruction.reconstructor import Reconstructor
from napari_ssdpc.settings.config import RunConfig
from napari_ssdpc.settings.optics import Optics
from napari_ssdpc.settings.reconstruction import DEFAULT_Z_UM
from napari_ssdpc.simulation import moving
from napari_ssdpc.simulation import phantoms as ph
from napari_ssdpc.simulation.multislice import Source
from napari_ssdpc.simulation.sample_free import flat_frame, white_frame
from napari_ssdpc.simulation.simulate import simulate

#: Condenser NA used for validation: σ = 0.75 puts the source edge across the outer lenslet rings,
#: which gives the largest parallax among phase-contrast views (docs/validation.md).
VALIDATION_NA = 0.3


@dataclass
class Case:
    """A simulated acquisition: raw, flat and white frames plus the truth.

    Attributes
    ----------
    name : str
    optics : Optics
        The optics simulated (with the phantom's medium).
    phantom : Phantom or list of Phantom
        The truth (a list: one per frame of a series).
    frame : ndarray, uint16, (H, W) or (T, H, W)
        Raw frame(s), ADU.
    flat, white : ndarray, uint16, (H, W)
        Flat frame (sample's condenser NA, no sample) and white frame (condenser fully open), ADU.
    grid : Grid
        The array as simulated (the truth for calibration).
    seconds : float
        Simulation time per frame, s.
    extra : dict
    """

    name: str
    optics: Optics
    phantom: object
    frame: np.ndarray
    flat: np.ndarray
    white: np.ndarray
    grid: Grid
    seconds: float = 0.0
    extra: dict = field(default_factory=dict)


def simulate_case(
    name, phantom, optics, *, cache_dir=None, seed=0, axis_offset_px=(3.7, -2.2), rotation_deg=0.4, source_step=2
) -> Case:
    """Simulate raw/flat/white frames (cached as .npz in ``cache_dir`` when given).

    Parameters
    ----------
    name : str
        Name of the case, also of its cache file.
    phantom : Phantom or list of Phantom
        The sample; a list simulates a series, one frame per phantom.
    optics : Optics
    cache_dir : Path, optional
        Folder of the .npz cache.
    seed : int
        Seed of the camera noise.
    axis_offset_px : (float, float)
        Misalignment of the array, px.
    rotation_deg : float
        Rotation of the array, degrees.
    source_step : int
        Spacing of the condenser's plane waves on the frequency lattice (``Source.step``); 4 is
        about four times faster than the default 2 (sweeps of many phantoms).

    Returns
    -------
    Case
    """
    optics = ph.optics_for(phantom, optics)
    grid = Grid.nominal(optics, axis_offset_px=axis_offset_px, rotation_deg=rotation_deg)
    step = "" if source_step == 2 else f"_step{source_step}"
    path = None if cache_dir is None else Path(cache_dir) / f"{name}_na{optics.condenser_na:g}_s{seed}{step}.npz"
    source = Source(step=source_step)
    # what the frames are of: a cached file of another phantom or instrument under the same name is
    # simulated again (files cached before this was kept are taken as they are)
    what = json.dumps([repr(phantom), optics.to_dict(), list(axis_offset_px), rotation_deg], default=str)
    if path is not None and path.is_file():
        d = np.load(path)
        if "what" not in d or str(d["what"]) == what:
            return Case(name, optics, phantom, d["frame"], d["flat"], d["white"], grid, float(d["seconds"]))
    rng = np.random.default_rng(seed)
    t0 = time.perf_counter()
    phs = phantom if isinstance(phantom, list) else [phantom]
    frames = np.stack([simulate(p, optics, grid=grid, rng=rng, source=source).frame for p in phs])
    seconds = (time.perf_counter() - t0) / len(phs)
    frame = frames if isinstance(phantom, list) else frames[0]
    flat = flat_frame(optics, grid=grid, rng=rng, source=source)
    white = white_frame(optics, grid=grid, rng=rng)
    if path is not None:
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            with atomic_write(path) as tmp, open(tmp, "wb") as f:
                np.savez_compressed(f, frame=frame, flat=flat, white=white, seconds=seconds, what=what)
        except OSError as e:  # the cache only saves time: go on without it
            warnings.warn(
                f"could not cache {name} in {path.parent} ({e.strerror}); it is simulated again next time",
                SsdpcWarning,
                stacklevel=2,
            )
    return Case(name, optics, phantom, frame, flat, white, grid, seconds)


def run_config(optics: Optics, *, z=DEFAULT_Z_UM, dz: float = 1.0, **settings) -> RunConfig:
    """The run configuration of a validation run.

    Parameters
    ----------
    optics : Optics
    z : (float, float)
        z range, µm.
    dz : float
        Plane spacing, µm.
    **settings
        Reconstruction keys (``method='wotf'``, ``rl={'iterations': 8}``, ``device='gpu'``, ...).

    Returns
    -------
    RunConfig
    """
    return RunConfig.of(optics, z_min_um=float(z[0]), z_max_um=float(z[1]), dz_um=float(dz), **settings)


def reconstruct_case(case: Case, *, z=DEFAULT_Z_UM, dz=1.0, stacks: bool = False, **settings):
    """Calibrate on the case's white frame and reconstruct its frame.

    Parameters
    ----------
    case : Case
    z : (float, float)
        z range, µm.
    dz : float
        Plane spacing, µm.
    stacks : bool
        Compute the directional stacks too.
    **settings
        Reconstruction keys (see :func:`run_config`).

    Returns
    -------
    result : Result
        Of the (first) frame.
    calibration : Calibration
    rec : Reconstructor
    """
    cal = calibrate(case.white, case.optics)
    rec = Reconstructor(run_config(case.optics, z=z, dz=dz, **settings), cal, flat=case.flat, stacks=stacks)
    frame = case.frame if case.frame.ndim == 2 else case.frame[0]
    return rec.reconstruct(frame), cal, rec


def paper_optics(condenser_na=VALIDATION_NA) -> Optics:
    """The paper's optics at the validation's condenser NA.

    Parameters
    ----------
    condenser_na : float
        Condenser NA.

    Returns
    -------
    Optics
    """
    return Optics.paper().replace(condenser_na=condenser_na)


CASES = {
    "bead": ph.pmma_bead,
    "two-beads": ph.two_beads,
    "cell": ph.cell,
    "weak-bead": ph.weak_bead,
    "moving-10": lambda: moving.moving_sample(20)[10],
    "bars": ph.bar_target,
}
