"""A job: everything that builds a Reconstructor, small enough to send to Dask workers."""

from __future__ import annotations

import functools
import hashlib
import json
from dataclasses import dataclass

import numpy as np

from napari_ssdpc._version import SOFTWARE
from napari_ssdpc.calibration.result import Calibration
from napari_ssdpc.reconstruction.checks import optics_in_use
from napari_ssdpc.settings.config import RunConfig

__all__ = ["Job"]


@dataclass
class Job:
    """The run configuration, the calibration and the flat: what every frame is reconstructed with.

    Parameters
    ----------
    config : RunConfig
        Optics, reconstruction settings (each method reads its own section) and outputs.
    calibration : Calibration
    flat : ndarray, (H, W), optional
        Flat frame, camera units.
    dark : float, optional
        Dark offset, camera units; None: estimated on every frame.
    stacks : bool
        Compute the directional stacks even where no output needs them.
    """

    config: RunConfig
    calibration: Calibration
    flat: np.ndarray | None = None
    dark: float | None = None
    stacks: bool = False

    def build(self, progress=None):
        """The Reconstructor of this job (operators built now).

        Parameters
        ----------
        progress : callable, optional
            ``progress(done, total, label)`` while the operators are built.

        Returns
        -------
        Reconstructor
        """
        from napari_ssdpc.reconstruction.reconstructor import Reconstructor

        return Reconstructor(
            self.config, self.calibration, flat=self.flat, dark=self.dark, stacks=self.stacks, progress=progress
        )

    def metadata(self, source: str | None = None) -> dict:
        """What every store and file of this job records beside its data (one shape for every face).

        Parameters
        ----------
        source : str, optional
            What the frames came from (a file's or a layer's name).

        Returns
        -------
        dict
            ``software``, ``source`` (when given), ``optics``, ``medium_index`` and ``calibration``
            (without the per-lenslet table); the sinks add each result's settings.
        """
        optics = optics_in_use(self.config.optics, self.calibration)  # with the calibration's aberrations
        meta = {
            "software": SOFTWARE,
            "optics": optics.to_dict(),
            "medium_index": optics.medium_index,
            "calibration": {k: v for k, v in self.calibration.to_dict().items() if k != "lenslets"},
        }
        return meta if source is None else {"source": str(source), **meta}

    @functools.cached_property
    def key(self) -> str:
        """Identifies the operators (a Dask worker's cache), the device included."""
        return self._hash(with_device=True)

    @functools.cached_property
    def result_key(self) -> str:
        """Identifies the results: the key without the device (CPU and GPU agree to float
        rounding), so that a series may be resumed on the other device."""
        return self._hash(with_device=False)

    def _hash(self, with_device: bool) -> str:
        rec = self.config.reconstruction.to_dict()
        if not with_device:
            rec.pop("device")
        h = hashlib.sha256()
        for part in (self.config.optics.to_dict(), self.calibration.to_dict(), rec, [self.dark, self.stacks]):
            h.update(json.dumps(part, sort_keys=True, default=str).encode())
        if self.flat is not None:
            h.update(np.ascontiguousarray(self.flat).tobytes())
        return h.hexdigest()[:16]
