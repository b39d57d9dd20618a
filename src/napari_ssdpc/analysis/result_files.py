"""A stored reconstruction read back for measurements: its Δn frames, grid, medium and α.

``ssdpc reconstruct`` writes one frame to OME-TIFF (RI in ``OUT.ome.tif``, Δn in
``OUT_delta_n.ome.tif`` where saved) and a series to an OME-Zarr store (one image group per
quantity, ``ssdpc_done`` marking the complete frames). Both carry our JSON description: the optics
(the medium's index), the reconstruction settings (the refraction increment) and the grid.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.settings.outputs import QUANTITIES

__all__ = ["StoredResult", "open_result"]

_HOW = "give an OME-TIFF or OME-Zarr result written by `ssdpc reconstruct`"


#: Refractive indices a sample or medium can have (air to the densest glasses and crystals).
RI_RANGE = (1.0, 2.5)


@dataclass
class StoredResult:
    """A reconstruction on disk, read one frame at a time.

    Attributes
    ----------
    path : Path
        The OME-TIFF or the ``.zarr`` store.
    z_um, y_um, x_um : ndarray, 1D
        Plane and pixel centres, µm.
    n_medium : float
        Refractive index of the medium.
    refraction_increment_um3_pg : float or None
        α the result was reconstructed with, µm³/pg (None: not recorded).
    frames : list of int
        The complete frames (a store being written holds fewer than its length).
    """

    path: Path
    z_um: np.ndarray
    y_um: np.ndarray
    x_um: np.ndarray
    n_medium: float
    refraction_increment_um3_pg: float | None
    frames: list[int]
    _data: object = field(repr=False, default=None)
    _is_ri: bool = field(repr=False, default=True)

    def delta_n(self, t: int) -> np.ndarray:
        """Δn of frame ``t``, (z, y, x) float32.

        Parameters
        ----------
        t : int
            Frame index (one of :attr:`frames`).

        Returns
        -------
        ndarray, float32, (z, y, x)
        """
        data = self._data
        try:
            vol = np.asarray(data[t] if getattr(data, "ndim", 0) == 4 else data, dtype=np.float32)  # type: ignore[index]
        except (OSError, ValueError, KeyError, TypeError, RuntimeError) as e:
            raise SsdpcError(
                f"{self.path}: frame {t} cannot be read ({type(e).__name__}); the file is damaged"
            ) from None
        vol = vol.reshape(len(self.z_um), len(self.y_um), len(self.x_um))
        bad = int(np.count_nonzero(~np.isfinite(vol)))
        if bad:
            raise SsdpcError(
                f"{self.path}: frame {t} holds {bad} voxel(s) that are not finite numbers; the file is damaged: "
                "reconstruct that frame again"
            )
        ri = vol if self._is_ri else vol + np.float32(self.n_medium)
        lo, hi = float(ri.min()), float(ri.max())
        if lo < RI_RANGE[0] or hi > RI_RANGE[1]:
            raise SsdpcError(
                f"{self.path}: frame {t} holds refractive indices from {lo:.4g} to {hi:.4g}, outside any sample's "
                f"({RI_RANGE[0]}-{RI_RANGE[1]}); the file is damaged or not an RI volume of ours"
            )
        return vol - np.float32(self.n_medium) if self._is_ri else vol

    def __iter__(self) -> Iterator[tuple[int, np.ndarray]]:
        """(t, Δn) of every complete frame, in order."""
        return ((t, self.delta_n(t)) for t in self.frames)


def _centred(n: int, step: float) -> np.ndarray:
    """Pixel centres of the pipeline's lateral grid: centred on the optical axis."""
    return (np.arange(n) - (n - 1) / 2) * step


def _medium(desc: dict, path: Path) -> float:
    n = (desc.get("optics") or {}).get("medium_index")
    if n is None:
        raise SsdpcError(f"{path} does not record the medium's index (its optics); {_HOW}")
    return float(n)


def _alpha(desc: dict) -> float | None:
    a = (desc.get("settings") or {}).get("refraction_increment_um3_pg")
    return None if a is None else float(a)


def _ours(desc) -> bool:
    return isinstance(desc, dict) and str(desc.get("software", "")).startswith("napari-ssdpc")


def _damaged(opener):
    """``opener(path)`` with damaged metadata (missing keys, text for numbers) as one line."""

    def read(path: Path) -> StoredResult:
        try:
            stored = opener(path)
        except (KeyError, IndexError, TypeError, ValueError, AttributeError) as e:
            raise SsdpcError(f"{path}: its metadata is damaged ({type(e).__name__}: {e}); {_HOW}") from None
        for name, c in (("z", stored.z_um), ("y", stored.y_um), ("x", stored.x_um)):
            if not np.all(np.isfinite(c)) or (len(c) > 1 and not np.all(np.diff(c) > 0)):
                raise SsdpcError(f"{path}: its {name} coordinates are not finite and increasing; {_HOW}")
        if not (np.isfinite(stored.n_medium) and RI_RANGE[0] <= stored.n_medium <= RI_RANGE[1]):
            raise SsdpcError(f"{path}: the medium's index {stored.n_medium} is not one of a medium; {_HOW}")
        return stored

    return read


@_damaged
def _open_zarr(path: Path) -> StoredResult:
    import zarr

    from napari_ssdpc.io.store import DONE, done_frames

    try:
        root: Any = zarr.open_group(str(path), mode="r")
    except Exception:
        raise SsdpcError(f"{path} is not an OME-Zarr store; {_HOW}") from None
    name = "delta_n" if "delta_n" in root else "ri"
    if name not in root or not _ours(dict(root[name].attrs).get("napari_ssdpc")):
        raise SsdpcError(f"{path} holds no RI volume of napari-ssdpc; {_HOW}")
    grp = root[name]
    desc = dict(grp.attrs["napari_ssdpc"])
    ms = grp.attrs["multiscales"][0]
    axes = "".join(a["name"] for a in ms["axes"]).upper()
    if axes not in ("TZYX", "ZYX"):
        raise SsdpcError(f"{path}/{name} has axes {axes}, not (t,) z, y, x; {_HOW}")
    transforms = {t["type"]: t[t["type"]] for t in ms["datasets"][0]["coordinateTransformations"]}
    dz, dy, dx = (float(v) for v in transforms["scale"][-3:])
    data = grp[ms["datasets"][0]["path"]]
    nz, ny, nx = data.shape[-3:]
    origin = transforms.get("translation")
    if origin is not None:
        z0, y0, x0 = (float(v) for v in origin[-3:])
        z, y, x = z0 + dz * np.arange(nz), y0 + dy * np.arange(ny), x0 + dx * np.arange(nx)
    else:
        z0 = float((desc.get("settings") or {}).get("z_min_um", -(nz - 1) / 2 * dz))
        z, y, x = z0 + dz * np.arange(nz), _centred(ny, dy), _centred(nx, dx)
    if axes == "ZYX":
        frames = [0]
    elif DONE in root:  # the frames marked complete that the image holds (flags claimed beyond it are not frames)
        frames = [t for t in done_frames(path).tolist() if t < data.shape[0]]
    else:
        frames = list(range(data.shape[0]))
    return StoredResult(path, z, y, x, _medium(desc, path), _alpha(desc), frames, data, name == "ri")


@_damaged
def _open_tiff(path: Path) -> StoredResult:
    import tifffile

    from napari_ssdpc.io.frames import tiff_info

    try:
        info = tiff_info(path)
    except Exception:
        raise SsdpcError(f"{path} is not a TIFF that can be read; {_HOW}") from None
    try:
        desc = json.loads((info.ome or {}).get("Description") or "")
    except ValueError:
        desc = None
    if not _ours(desc):
        raise SsdpcError(f"{path} is not a result of napari-ssdpc (no description of ours); {_HOW}")
    what = desc.get("quantity")
    kinds = {QUANTITIES["ri"].description: True, QUANTITIES["delta_n"].description: False}
    if what not in kinds:
        raise SsdpcError(f"{path} holds the {what}, not RI or Δn; give the RI file OUT.ome.tif of the result")
    pixels = (info.ome or {}).get("Pixels", {})
    dy, dx = float(pixels.get("PhysicalSizeY", 0) or 0), float(pixels.get("PhysicalSizeX", 0) or 0)
    if not (dy > 0 and dx > 0):
        raise SsdpcError(f"{path} records no pixel size; {_HOW}")
    data = tifffile.imread(path)
    z = np.asarray(desc.get("z_um") or [], dtype=np.float64)
    if z.size == 0 or data.size != z.size * data.shape[-2] * data.shape[-1]:
        raise SsdpcError(f"{path}: its planes do not match the z grid it records; {_HOW}")
    y, x = _centred(data.shape[-2], dy), _centred(data.shape[-1], dx)
    return StoredResult(path, z, y, x, _medium(desc, path), _alpha(desc), [0], data, kinds[what])


def open_result(path) -> StoredResult:
    """Open a result written by ``ssdpc reconstruct`` (or napari-ssdpc's writer).

    Parameters
    ----------
    path : str or Path
        ``OUT.ome.tif`` (one frame: RI, or Δn ``OUT_delta_n.ome.tif``) or ``OUT.zarr`` (a series; its
        Δn image where saved, else RI).

    Returns
    -------
    StoredResult

    Raises
    ------
    SsdpcError
        Missing, or not a result of ours (one line that names what to give).
    """
    path = Path(path)
    if not path.exists():
        raise SsdpcError(f"file not found: {path} (check the path)")
    if path.is_dir():
        return _open_zarr(path)
    if path.name.lower().endswith((".tif", ".tiff")):
        return _open_tiff(path)
    raise SsdpcError(f"{path} is neither an OME-TIFF nor an OME-Zarr store; {_HOW}")
