"""napari sample data: simulated frames, shipped or generated on demand and cached (no downloads).

- ``pmma_bead_sample``: the paper's PMMA bead (13 µm, n 1.49 in oil 1.518), its flat frame
  (same condenser NA 0.3) and a white frame (condenser fully open, for calibration), paper optics
  with a 1024 x 1024 px camera region that holds the whole pupil. The three frames ship with the
  package (``data/``, 3 MB, written by :func:`ship_frames`), so the sample opens in about
  0.5 s; were they stale, it would be simulated (about a minute on two cores) and cached.
- ``moving_sample_series``: a swimming cell-like sample in water (``moving.moving_sample`` with
  :data:`SERIES_CELL`, a cell 'tv' measures right),
  20 frames, the bead's optics (condenser NA 0.3, where the lenslets carry phase contrast, and the
  1024 x 1024 px region). Reduced cost: the condenser disk is sampled every 4 lattice units
  (``Source(step=4)``; at most 3 % of the peak intensity different from the full sampling; about
  30 s a frame on two cores). Its flat, white and first frames ship with the package, so it opens
  at once; the series is a lazy dask array whose other frames a background thread simulates and
  caches as soon as the sample opens, onward from the last frame read; a frame read before the
  thread reaches it (on the time slider or by the Reconstruct widget) waits for it, never for a
  second simulation of it.

The cache lives in ``$NAPARI_SSDPC_CACHE`` (default ``~/.cache/napari-ssdpc``) under the package
version; file names carry a hash of everything that made the frame, so a changed setting never
reads a stale file.
"""

from __future__ import annotations

from functools import partial
from pathlib import Path

import numpy as np

from napari_ssdpc import __version__
from napari_ssdpc._napari import sample_cache, turns
from napari_ssdpc._napari.placement import fit_view, frame_transform

#: Sample frames shipped with the package (``ship_frames``): the samples open at once.
#: The bead sample's camera region of interest (px): the whole objective pupil (radius 435 px) fits.
BEAD_ROI_PX = 1024
SERIES_FRAMES = 20
SOURCE = "napari-ssdpc simulator"  # the samples' frames say where they come from
SERIES_SOURCE_STEP = 4  # reduced-cost source sampling of the time series (see module doc)
#: The moving sample's cell: n 1.345 with an inclusion of 1.365 in water (about 2 rad through it,
#: where 'tv' reads its dry mass, 63.1 pg, within 5 %; the simulator's default swimmer of 1.36 and
#: 1.42, 5.4 rad, read 1.16-1.26 x with the dock's defaults).
SERIES_CELL = {"n": 1.345, "n_nucleus": 1.365}


def _physics(optics) -> dict:
    """The optics as they enter the simulation (reconstruction settings and name left out)."""
    return {k: v for k, v in optics.to_dict().items() if k != "name"}


def _optics_meta(optics, name: str) -> dict:
    """Layer metadata: the optics (the Optics widget can adopt them) and a YAML copy in the cache."""
    path = sample_cache.cache_dir() / f"{name}-optics.yaml"
    optics.to_yaml(path)
    return {
        "ssdpc": {
            "kind": "raw",
            "optics": optics.to_dict(),
            "optics_yaml": str(path),
            "source": SOURCE,
        }
    }


def _role(meta: dict, frame: str) -> dict:
    """A layer's own copy of the sample's metadata, with what the frame is ('raw', 'flat', 'white')."""
    return {"ssdpc": {**meta["ssdpc"], "frame": frame}}


def _fit_view_on_arrival() -> None:
    """Fit the current viewer's view to the sample's raw frame when napari adds it (napari fits
    the view to the first layers of a viewer only: a sample opened beside others was left off view)."""
    import napari

    viewer = napari.current_viewer()
    if viewer is None:
        return

    def inserted(event):
        info = event.value.metadata.get("ssdpc", {})
        if info.get("frame") == "raw" and info.get("source") == SOURCE:
            viewer.layers.events.inserted.disconnect(inserted)
            fit_view(viewer, event.value)

    viewer.layers.events.inserted.connect(inserted)


def _contrast(frame) -> list[float]:
    lo, hi = np.percentile(np.asarray(frame)[::4, ::4], [1, 99.9])
    return [float(lo), float(max(hi, lo + 1))]


def _rest_in_turns(layers: list) -> list:
    """A sample's layers as File › Open Sample hands them to napari, which adds them all in one
    event: the last (the raw frame, shown) is left to napari; the others (the hidden flat and white
    frames) are put below it, each on a turn of the event loop of its own (:mod:`.turns`). Without
    a viewer, all of them."""
    import napari

    viewer = napari.current_viewer()
    if viewer is None:
        return layers
    for data, kwargs, kind in reversed(layers[:-1]):
        turns.later(partial(_insert_below, viewer, data, kwargs, kind))
    return layers[-1:]


def _insert_below(viewer, data, kwargs: dict, kind: str) -> None:
    from napari.layers import Layer

    viewer.layers.insert(0, Layer.create(data, kwargs, kind))


def open_pmma_bead() -> list:
    """File › Open Sample › PMMA bead: :func:`pmma_bead_sample`, its flat and white frames on turns
    of their own."""
    return _rest_in_turns(pmma_bead_sample())


def open_moving_sample() -> list:
    """File › Open Sample › moving sample: :func:`moving_sample_series`, its flat and white frames
    on turns of their own."""
    return _rest_in_turns(moving_sample_series())


# ---------------------------------------------------------------------------- bead
def sample_optics(medium_index: float | None = None):
    """The samples' optics: the paper's at condenser NA 0.3 (the condenser-NA sweep of
    docs/validation.md) on a 1024 x 1024 px camera region that holds the whole pupil.

    Parameters
    ----------
    medium_index : float, optional
        The immersion medium (default the paper's oil).

    Returns
    -------
    Optics
    """
    from napari_ssdpc.settings.optics import Optics

    optics = Optics.paper().replace(
        condenser_na=0.3, width_px=BEAD_ROI_PX, height_px=BEAD_ROI_PX, name="paper optics, 1024 px region"
    )
    return optics if medium_index is None else optics.replace(medium_index=medium_index)


def bead_frames():
    """(frame, flat, white, optics) of the PMMA bead with the paper's optics at condenser NA 0.3.

    At NA 0.3 (sigma 0.75) the outer lenslet rings straddle the source edge and the bead is a
    bead (axial FWHM ~16 µm); at the paper optics' 0.1 only four lenslets carry phase and it
    would be a needle over 100 µm long.
    """
    optics = sample_optics()
    base = (_physics(optics), __version__)

    def simulated(kind: str, seed: int):  # only when the shipped frames are stale: the simulator loads then
        from napari_ssdpc.simulation.phantoms import pmma_bead
        from napari_ssdpc.simulation.sample_free import flat_frame, white_frame
        from napari_ssdpc.simulation.simulate import simulate

        rng = np.random.default_rng(seed)
        if kind == "bead":
            return simulate(pmma_bead(), optics, rng=rng).frame
        return (flat_frame if kind == "flat" else white_frame)(optics, rng=rng)

    frame = sample_cache.cached("pmma_bead", lambda: simulated("bead", 0), sample_cache.key("bead", *base, 0))
    flat = sample_cache.cached("pmma_bead_flat", lambda: simulated("flat", 1), sample_cache.key("flat", *base, 1))
    white = sample_cache.cached("pmma_bead_white", lambda: simulated("white", 2), sample_cache.key("white", *base, 2))
    return frame, flat, white, optics


def ship_frames(folder: Path = sample_cache.SHIPPED) -> list[Path]:
    """Write the frames that open a sample at once (zlib-compressed TIFFs) where the package reads
    them first: the bead's three, and the time series' flat, white and first frames.

    Run after a change of the simulator or of the sample's optics (the file names carry a hash
    of both, so stale frames are never read; the sample is then simulated on first use).

    Parameters
    ----------
    folder : Path
        Default: the package's ``_napari/data``.

    Returns
    -------
    list of Path
        The files written.
    """
    import tifffile

    from napari_ssdpc.io.frames import read_frame

    bead_frames()  # simulated into the cache if needed
    series_flat_white()
    series_frame(0)
    folder.mkdir(parents=True, exist_ok=True)
    out = []
    shipped = ("pmma_bead*.tif", "moving_flat-*.tif", "moving_white-*.tif", f"moving_{SERIES_FRAMES}_000-*.tif")
    for made in sorted(p for pattern in shipped for p in sample_cache.cache_dir().glob(pattern)):
        frame = read_frame(made, name="sample frame")
        if frame.shape == (BEAD_ROI_PX, BEAD_ROI_PX):
            tifffile.imwrite(folder / made.name, frame, compression="zlib", photometric="minisblack")
            out.append(folder / made.name)
    return out


def pmma_bead_sample():
    """The paper's PMMA bead (13 µm, n 1.49 in 1.518), its flat and white frames, paper optics at
    condenser NA 0.3."""
    frame, flat, white, optics = bead_frames()
    _fit_view_on_arrival()
    meta = _optics_meta(optics, "paper")
    lims = _contrast(frame)
    um = frame_transform(optics, 2)  # in the volume's µm (placement.py)
    return [
        (
            white,
            {
                "name": "PMMA bead white",
                "metadata": _role(meta, "white"),
                "visible": False,
                "contrast_limits": lims,
                **um,
            },
            "image",
        ),
        (
            flat,
            {
                "name": "PMMA bead flat",
                "metadata": _role(meta, "flat"),
                "visible": False,
                "contrast_limits": lims,
                **um,
            },
            "image",
        ),
        (frame, {"name": "PMMA bead", "metadata": _role(meta, "raw"), "contrast_limits": lims, **um}, "image"),
    ]


# ---------------------------------------------------------------------- time series
def series_optics():
    """The samples' optics with water as the medium (the moving sample swims in water)."""
    return sample_optics(medium_index=1.33)


def series_frame(i: int, n_frames: int = SERIES_FRAMES) -> np.ndarray:
    """Frame ``i`` of the moving-sample series (simulated once, then cached).

    Parameters
    ----------
    i : int
        Frame index.
    n_frames : int

    Returns
    -------
    ndarray, uint16, (H, W)
    """
    from napari_ssdpc.simulation.moving import moving_sample

    optics = series_optics()
    phantom = moving_sample(n_frames, **SERIES_CELL)[i]
    key = sample_cache.key("moving", _physics(optics), repr(phantom), SERIES_SOURCE_STEP, 1000 + i, __version__)

    def simulated():  # only when not shipped nor cached: the simulator loads then
        from napari_ssdpc.simulation.multislice import Source
        from napari_ssdpc.simulation.simulate import simulate

        source, rng = Source(step=SERIES_SOURCE_STEP), np.random.default_rng(1000 + i)
        return simulate(phantom, optics, source=source, rng=rng, progress=sample_cache.unless_exiting).frame

    return sample_cache.cached(f"moving_{n_frames}_{i:03d}", simulated, key)


def series_flat_white():
    """Flat (same reduced source sampling as the series) and white frames of the series' optics."""
    optics = series_optics()
    base = (_physics(optics), SERIES_SOURCE_STEP, __version__)

    def simulated(kind: str, seed: int):  # only when not shipped nor cached: the simulator loads then
        from napari_ssdpc.simulation.multislice import Source
        from napari_ssdpc.simulation.sample_free import flat_frame, white_frame

        rng = np.random.default_rng(seed)
        if kind == "flat":
            return flat_frame(optics, source=Source(step=SERIES_SOURCE_STEP), rng=rng)
        return white_frame(optics, rng=rng)

    flat = sample_cache.cached("moving_flat", lambda: simulated("flat", 3), sample_cache.key("flat", *base, 3))
    white = sample_cache.cached("moving_white", lambda: simulated("white", 4), sample_cache.key("white", *base, 4))
    return flat, white


class SeriesPrefetch(sample_cache.Prefetch):
    """The time-series sample's frames simulated in the background (:class:`~.sample_cache.Prefetch`).

    Parameters
    ----------
    n_frames : int
    """

    def __init__(self, n_frames: int):
        super().__init__(lambda i: series_frame(i, n_frames), n_frames)


def series_array(n_frames: int = SERIES_FRAMES, prefetch: bool = True):
    """Lazy (t, y, x) dask array: frame i is simulated (or read from the cache) when first used.

    Parameters
    ----------
    n_frames : int
    prefetch : bool
        Simulate the frames in a background thread at once (:class:`SeriesPrefetch`).

    Returns
    -------
    dask.array.Array, uint16, (t, H, W)
    """
    import dask
    import dask.array as da

    optics = series_optics()
    shape = (optics.height_px, optics.width_px)
    ahead = SeriesPrefetch(n_frames) if prefetch else None

    def frame(i: int) -> np.ndarray:
        if ahead is not None:
            ahead.asked(i)
        return series_frame(i, n_frames)

    tag = sample_cache.key("moving", _physics(optics), SERIES_SOURCE_STEP, __version__)  # names the series for resuming
    frames = [
        da.from_delayed(dask.delayed(frame)(i), shape, dtype=np.uint16, name=f"moving-sample-{tag}-{n_frames}-{i}")
        for i in range(n_frames)
    ]
    return da.stack(frames)


def moving_sample_series(n_frames: int = SERIES_FRAMES, prefetch: bool = True):
    """A swimming cell-like sample in water, ``n_frames`` frames (lazy, simulated in the background
    and on demand), with its flat and white frames.

    Parameters
    ----------
    n_frames : int
    prefetch : bool
        Simulate every frame in a background thread from the start (see :func:`series_array`).

    Returns
    -------
    list of (data, kwargs, 'image')
    """
    flat, white = series_flat_white()
    optics = series_optics()
    _fit_view_on_arrival()
    meta = _optics_meta(optics, "water")
    lims = _contrast(flat)
    series = series_array(n_frames, prefetch)
    um = frame_transform(optics, 2)  # in the volume's µm (placement.py)
    return [
        (
            white,
            {
                "name": "moving sample white",
                "metadata": _role(meta, "white"),
                "visible": False,
                "contrast_limits": lims,
                **um,
            },
            "image",
        ),
        (
            flat,
            {
                "name": "moving sample flat",
                "metadata": _role(meta, "flat"),
                "visible": False,
                "contrast_limits": lims,
                **um,
            },
            "image",
        ),
        (
            series,
            {
                "name": "moving sample",
                "metadata": _role(meta, "raw"),
                "contrast_limits": lims,
                "axis_labels": ("t", "y", "x"),
                **frame_transform(optics, 3),
            },
            "image",
        ),
    ]
