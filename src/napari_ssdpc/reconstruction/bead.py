"""One bead fitted as a sphere: its centre, diameter, index and the checks of its fit
(:mod:`~napari_ssdpc.reconstruction.beads`)."""

from __future__ import annotations

from dataclasses import asdict, dataclass

__all__ = ["Bead"]


@dataclass(frozen=True)
class Bead:
    """One fitted bead.

    Attributes
    ----------
    centre_um : tuple of float
        (x, y, z), µm (z > 0: farther from the objective).
    diameter_um : float
    ri : float
        Its refractive index (the medium's plus Δn).
    delta_n : float
        Its index minus the medium's.
    residual_over_noise : float or None
        Mean squared residual of the views over its footprint, in noise variances.
    stop_over_noise : float
        The residual the model reaches on a well-explained bead (the noise and the model's error).
    converged : bool
        The fit ended on its convergence test.
    explained : bool
        The residual is within twice the stop.
    note : str
        What a user must know before trusting it ('' when nothing): not converged, not explained,
        overlapping another bead.
    first_answer_ratio : float or None
        The voxel answer the beads were found in (e.g. 'tv'), checked against the sphere: its
        integrated Δn around the bead
        (:func:`~napari_ssdpc.reconstruction.fit_objects.around_bead`) over the sphere's volume x Δn.
    """

    centre_um: tuple[float, float, float]
    diameter_um: float
    ri: float
    delta_n: float
    residual_over_noise: float | None
    stop_over_noise: float
    converged: bool
    explained: bool
    note: str = ""
    first_answer_ratio: float | None = None

    def to_dict(self) -> dict:
        """Plain numbers for JSON."""
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> Bead:
        """The bead :meth:`to_dict` wrote (e.g. into a frame's report).

        Parameters
        ----------
        d : dict
            Its fields, the centre as a list or a tuple.

        Returns
        -------
        Bead
        """
        return cls(**{**d, "centre_um": tuple(d["centre_um"])})
