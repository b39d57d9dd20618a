"""Per-object measurements over a series, linked into tracks, as rows and a CSV beside the result.

``measure_series`` runs :func:`~napari_ssdpc.analysis.objects.measure_objects` on every frame and
:func:`~napari_ssdpc.analysis.tracks.link_tracks` over them; ``measure_result`` does it for a
stored result and writes ``RESULT_objects.csv`` (``ssdpc measure``).
"""

from __future__ import annotations

import csv
import math
from collections.abc import Callable, Iterable
from pathlib import Path

import numpy as np

from napari_ssdpc.analysis.objects import DEFAULT_RULE, REFRACTION_INCREMENT_UM3_PG, ObjectRule, measure_objects
from napari_ssdpc.analysis.result_files import open_result
from napari_ssdpc.analysis.tracks import DEFAULT_MAX_STEP_UM, link_tracks
from napari_ssdpc.errors import SsdpcError

__all__ = ["COLUMNS", "csv_path", "is_objects_table", "measure_result", "measure_series", "read_csv", "write_csv"]

#: The CSV's columns, units in their names (docs/measurements.md).
COLUMNS = (
    "t",
    "track",
    "object",
    "x_um",
    "y_um",
    "z_um",
    "volume_um3",
    "mean_ri",
    "peak_ri",
    "integrated_dn_um3",
    "dry_mass_pg",
    "voxels",
    "at_edge",
    "noise_dn",
    "threshold_dn",
)


def measure_series(
    frames: Iterable[tuple[int, np.ndarray]],
    z_um,
    y_um,
    x_um,
    *,
    n_medium: float,
    rule: ObjectRule = DEFAULT_RULE,
    refraction_increment_um3_pg: float = REFRACTION_INCREMENT_UM3_PG,
    max_step_um: float = DEFAULT_MAX_STEP_UM,
    progress: Callable | None = None,
    total: int | None = None,
) -> list[dict]:
    """Objects of every frame, measured and linked into tracks.

    Parameters
    ----------
    frames : iterable of (int, ndarray)
        (t, Δn (z, y, x)) in time order.
    z_um, y_um, x_um : ndarray, 1D
        The grid, µm.
    n_medium : float
        Refractive index of the medium.
    rule : ObjectRule
        How objects are found.
    refraction_increment_um3_pg : float
        α, µm³/pg.
    max_step_um : float
        The largest centroid step between frames that continues a track, µm.
    progress : callable, optional
        ``progress(done, total)`` after each frame.
    total : int, optional
        Frames to expect (for ``progress``).

    Returns
    -------
    list of dict
        One row per object and frame, the keys of :data:`COLUMNS`.
    """
    times, per_frame = [], []
    for done, (t, dn) in enumerate(frames, start=1):
        times.append(int(t))
        per_frame.append(
            measure_objects(
                dn,
                z_um,
                y_um,
                x_um,
                n_medium=n_medium,
                rule=rule,
                refraction_increment_um3_pg=refraction_increment_um3_pg,
            )
        )
        if progress is not None:
            progress(done, total if total is not None else done)
    rows = []
    for t, objects in zip(times, link_tracks(per_frame, max_step_um)):
        rows += [{"t": t, **o} for o in objects]
    return rows


def csv_path(result) -> Path:
    """``RESULT_objects.csv`` beside a result (``OUT.ome.tif`` or ``OUT.zarr``).

    Parameters
    ----------
    result : str or Path

    Returns
    -------
    Path
    """
    result = Path(result)
    name = result.name.rstrip("/")
    for suffix in (".ome.tiff", ".ome.tif", ".tiff", ".tif", ".zarr"):
        if name.lower().endswith(suffix):
            name = name[: -len(suffix)]
            break
    return result.with_name(f"{name}_objects.csv")


def is_objects_table(path) -> bool:
    """Whether a file is an objects table napari-ssdpc wrote (its header is :data:`COLUMNS`).

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    bool
    """
    try:
        with open(path, encoding="utf-8") as f:
            return f.readline().strip() == ",".join(COLUMNS)
    except (OSError, UnicodeDecodeError):
        return False


def write_csv(rows: list[dict], path, *, inputs: dict | None = None, overwrite: bool = False) -> Path:
    """Write the rows as CSV, atomically; a file napari-ssdpc did not write is refused.

    Parameters
    ----------
    rows : list of dict
        With the keys of :data:`COLUMNS`.
    path : str or Path
        The CSV.
    inputs : dict, optional
        {role: path} of the inputs it must not overwrite.
    overwrite : bool
        Replace any existing file.

    Returns
    -------
    Path
    """
    from napari_ssdpc.files import atomic_write
    from napari_ssdpc.io.paths import check_outputs

    path = check_outputs({"objects table": path}, inputs or {}, overwrite=overwrite, replaceable=is_objects_table)[
        "objects table"
    ]
    with atomic_write(path) as tmp, open(tmp, "w", newline="", encoding="utf-8") as f:
        writer = csv.DictWriter(f, fieldnames=COLUMNS, extrasaction="ignore")
        writer.writeheader()
        for r in rows:
            writer.writerow({k: _cell(r[k]) for k in COLUMNS})
    return path


def _cell(v):
    if isinstance(v, float):
        return "nan" if math.isnan(v) else f"{v:.6g}" if abs(v) < 1e-3 or abs(v) >= 1e5 else f"{v:.6f}".rstrip("0")
    return v


def read_csv(path) -> list[dict]:
    """Rows of an objects table (numbers as int or float).

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    list of dict
    """
    ints = {"t", "track", "object", "voxels", "at_edge"}
    with open(path, encoding="utf-8", newline="") as f:
        return [{k: int(v) if k in ints else float(v) for k, v in r.items()} for r in csv.DictReader(f)]


def measure_result(
    result,
    out=None,
    *,
    rule: ObjectRule = DEFAULT_RULE,
    refraction_increment_um3_pg: float | None = None,
    max_step_um: float = DEFAULT_MAX_STEP_UM,
    overwrite: bool = False,
    progress: Callable | None = None,
) -> tuple[list[dict], Path]:
    """Measure the objects of a stored result and write the CSV beside it.

    Parameters
    ----------
    result : str or Path
        ``OUT.ome.tif`` or ``OUT.zarr`` written by ``ssdpc reconstruct``.
    out : str or Path, optional
        The CSV (default: ``RESULT_objects.csv`` beside the result).
    rule : ObjectRule
        How objects are found.
    refraction_increment_um3_pg : float, optional
        α, µm³/pg; default: the one the result was reconstructed with.
    max_step_um : float
        Tracks: the largest step between frames, µm.
    overwrite : bool
        Replace an existing CSV napari-ssdpc did not write.
    progress : callable, optional
        ``progress(done, total)`` per frame.

    Returns
    -------
    rows : list of dict
    path : Path
        The CSV written.
    """
    out = csv_path(result) if out is None else Path(out)
    stored = open_result(result)
    from napari_ssdpc.io.paths import check_outputs

    check_outputs({"objects table": out}, {"result": result}, overwrite=overwrite, replaceable=is_objects_table)
    if not stored.frames:
        raise SsdpcError(f"{result} holds no complete frame yet; reconstruct it first")
    alpha = refraction_increment_um3_pg or stored.refraction_increment_um3_pg or REFRACTION_INCREMENT_UM3_PG
    rows = measure_series(
        iter(stored),
        stored.z_um,
        stored.y_um,
        stored.x_um,
        n_medium=stored.n_medium,
        rule=rule,
        refraction_increment_um3_pg=alpha,
        max_step_um=max_step_um,
        progress=progress,
        total=len(stored.frames),
    )
    return rows, write_csv(rows, out, inputs={"result": result}, overwrite=overwrite)
