"""Objects over time as napari layers: the centroids as a Tracks layer (µm, with every measurement
as a feature), measured from a result layer or read from an objects table (``*_objects.csv``).

The dock that shows the table and the plots is :mod:`.objects_dock`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from napari_ssdpc.analysis.objects import DEFAULT_RULE, REFRACTION_INCREMENT_UM3_PG, ObjectRule
from napari_ssdpc.analysis.table import COLUMNS, is_objects_table, measure_series, read_csv
from napari_ssdpc.analysis.tracks import DEFAULT_MAX_STEP_UM
from napari_ssdpc.errors import SsdpcError

__all__ = ["get_objects_reader", "measure_layer", "read_objects", "tracks_layer"]


def tracks_layer(rows: list[dict], name: str = "objects"):
    """Layer data tuple of a Tracks layer: one track per object, vertices (track, t, z, y, x) in µm.

    Parameters
    ----------
    rows : list of dict
        Rows of an objects table (:data:`~napari_ssdpc.analysis.table.COLUMNS`).
    name : str
        Layer name.

    Returns
    -------
    tuple
        napari's (data (N, 5), kwargs, 'tracks'); every column is a feature, coloured by dry mass.
    """
    if not rows:
        raise SsdpcError("no objects were found: lower the thresholds (k, k_low) or the minimum volume")
    rows = sorted(rows, key=lambda r: (r["track"], r["t"]))
    data = np.array([[r["track"], r["t"], r["z_um"], r["y_um"], r["x_um"]] for r in rows], dtype=np.float64)
    features = {c: np.array([r[c] for r in rows]) for c in COLUMNS}
    kwargs = {
        "name": name,
        "features": features,
        "color_by": "dry_mass_pg",
        "tail_length": 1000,
        "axis_labels": ("t", "z", "y", "x"),
        "units": ("pixel", "µm", "µm", "µm"),
        "metadata": {"ssdpc": {"kind": "objects"}},
    }
    return (data, kwargs, "tracks")


def measure_layer(
    data,
    scale,
    translate,
    info: dict,
    *,
    rule: ObjectRule = DEFAULT_RULE,
    max_step_um: float = DEFAULT_MAX_STEP_UM,
    progress=None,
) -> list[dict]:
    """Objects of a result layer (RI or Δn, (z, y, x) or (t, z, y, x)), measured and tracked.

    Parameters
    ----------
    data : array_like
        The layer's data; frames all NaN (not yet written) are skipped.
    scale, translate : sequence of float
        The layer's voxel size and origin; the last three are (z, y, x) in µm.
    info : dict
        The layer's ``metadata['ssdpc']`` (quantity, optics with the medium's index, settings).
    rule : ObjectRule
    max_step_um : float
        Tracks: the largest step between frames, µm.
    progress : callable, optional
        ``progress(done, total)`` per frame.

    Returns
    -------
    list of dict
        Rows of the objects table.
    """
    quantity = info.get("quantity")
    if quantity not in ("ri", "delta_n"):
        raise SsdpcError("choose an RI (or Δn) layer of a reconstruction to measure its objects")
    n_medium = info.get("medium_index") or (info.get("optics") or {}).get("medium_index")
    if n_medium is None:
        raise SsdpcError("the layer does not record the medium's index; open the result file or reconstruct again")
    alpha = (info.get("settings") or {}).get("refraction_increment_um3_pg") or REFRACTION_INCREMENT_UM3_PG
    series = data if np.ndim(data) == 4 else data[np.newaxis]
    shape = series.shape[-3:]
    z, y, x = (float(o) + float(s) * np.arange(n) for o, s, n in zip(translate[-3:], scale[-3:], shape))
    offset = float(n_medium) if quantity == "ri" else 0.0

    def frames():
        for t in range(series.shape[0]):
            vol = np.asarray(series[t], dtype=np.float32)
            if np.isfinite(vol).any():
                yield t, vol - np.float32(offset)

    return measure_series(
        frames(),
        z,
        y,
        x,
        n_medium=float(n_medium),
        rule=rule,
        refraction_increment_um3_pg=float(alpha),
        max_step_um=max_step_um,
        progress=progress,
        total=series.shape[0],
    )


def read_objects(path):
    """An objects table as a Tracks layer.

    Parameters
    ----------
    path : str or Path
        ``RESULT_objects.csv`` written by ``ssdpc measure``.

    Returns
    -------
    list of tuple
        One (data, kwargs, 'tracks').
    """
    p = Path(path)
    return [tracks_layer(read_csv(p), name=p.stem)]


def get_objects_reader(path):
    """Reader for the objects tables of napari-ssdpc, or None for any other file.

    Parameters
    ----------
    path : str or list of str

    Returns
    -------
    callable or None
    """
    p = Path(path[0] if isinstance(path, list) else path)
    return read_objects if p.suffix.lower() == ".csv" and p.is_file() and is_objects_table(p) else None
