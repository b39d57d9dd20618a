"""What a real instrument adds to its nominal optics: the objective's aberration and each lenslet's own
sub-aperture (docs/aberrations.md).

- The objective's wavefront over its pupil, W(u) = Σ_j c_j Z_j(|u| / (NA/λ), θ), in waves, Zernike
  polynomials in Noll's order and rms normalisation (:mod:`napari_ssdpc.physics.zernike`): a
  coverslip or immersion mismatch is mostly primary spherical aberration, Noll j = 11.
- The condenser's disk off the optical axis: its centre in NA units (x, y).
- Per lenslet (by its lattice row and column): the centre of its sub-aperture moved in the MLA plane
  (µm), its radius scaled, and a defocus of its view, the wavefront d·r² at r = |u − u_k| / ρ
  (waves at the sub-aperture's edge: a lenslet focal length or sensor distance that differs from the
  nominal).

All zero (the default) is the nominal instrument: every model gives exactly the numbers it gives
without this section.
"""

from __future__ import annotations

from pydantic import Field, StrictFloat, model_validator

from napari_ssdpc.settings.base import SettingsModel, bounded

__all__ = ["Aberrations", "LensletTerms"]

#: Largest |coefficient| taken, waves: beyond it the pupil's phase is not sampled by the models.
MAX_WAVES = 10.0


class LensletTerms(SettingsModel):
    """One lenslet's departure from the nominal array."""

    row: int = Field(..., description="the lenslet's lattice row")
    col: int = Field(..., description="the lenslet's lattice column")
    offset_um: tuple[StrictFloat, StrictFloat] = Field(
        (0.0, 0.0), strict=False, description="its sub-aperture's centre moved in the MLA plane (x, y), µm"
    )
    radius_scale: float = bounded(1.0, 0.5, 1.5, "its sub-aperture's radius over the nominal one")
    defocus_waves: float = bounded(
        0.0, -MAX_WAVES, MAX_WAVES, "its view's defocus: the wavefront at the sub-aperture's edge, waves"
    )

    @property
    def is_nominal(self) -> bool:
        """Whether the lenslet is as designed."""
        return self.offset_um == (0.0, 0.0) and self.radius_scale == 1.0 and self.defocus_waves == 0.0


class Aberrations(SettingsModel):
    """The objective's Zernike terms and the lenslets' own terms; all zero is the nominal instrument."""

    objective_zernike_waves: tuple[StrictFloat, ...] = Field(
        (),
        strict=False,
        description="the objective's wavefront, Noll j = 1, 2, ... (rms-normalised), waves; j = 11 is spherical",
    )
    lenslets: tuple[LensletTerms, ...] = Field((), strict=False, description="lenslets that differ from the array")
    condenser_offset_na: tuple[StrictFloat, StrictFloat] = Field(
        (0.0, 0.0), strict=False, description="the condenser disk's centre off the optical axis (x, y), NA"
    )

    @model_validator(mode="after")
    def _modelled(self) -> Aberrations:
        big = [c for c in self.objective_zernike_waves if abs(c) > MAX_WAVES]
        if big:
            raise ValueError(f"a coefficient of {big[0]} waves; at most ±{MAX_WAVES:g} is modelled")
        keys = [(t.row, t.col) for t in self.lenslets]
        if len(set(keys)) != len(keys):
            raise ValueError("a lenslet is named twice; give each (row, col) once")
        return self

    @property
    def is_nominal(self) -> bool:
        """Whether nothing differs from the nominal optics."""
        return (
            not any(self.objective_zernike_waves)
            and all(t.is_nominal for t in self.lenslets)
            and self.condenser_offset_na == (0.0, 0.0)
        )

    def lenslet(self, row: int, col: int) -> LensletTerms:
        """The terms of lenslet (row, col); nominal where none are given.

        Parameters
        ----------
        row, col : int
            The lenslet's lattice row and column.

        Returns
        -------
        LensletTerms
        """
        for t in self.lenslets:
            if (t.row, t.col) == (row, col):
                return t
        return LensletTerms(row=row, col=col)

    def with_defocus(self, keys, defocus) -> Aberrations:
        """These aberrations with the given lenslets' defocus (their other terms kept).

        Parameters
        ----------
        keys : sequence of (int, int)
            The lenslets' (row, col).
        defocus : sequence of float
            Their defocus, waves at the sub-aperture's edge (rounded to 0.0001).

        Returns
        -------
        Aberrations
        """
        terms = {(t.row, t.col): t for t in self.lenslets}
        for (row, col), d in zip(keys, defocus, strict=True):
            old = terms.get((row, col), LensletTerms(row=row, col=col))
            terms[(row, col)] = old.model_copy(update={"defocus_waves": round(float(d), 4)})
        return self.model_copy(update={"lenslets": tuple(terms.values())})

    def with_zernike(self, noll, coefficients) -> Aberrations:
        """These aberrations with the given objective terms (the others kept).

        Parameters
        ----------
        noll : sequence of int
            Noll indices.
        coefficients : sequence of float
            Their coefficients, waves rms (rounded to 0.0001).

        Returns
        -------
        Aberrations
        """
        c = list(self.objective_zernike_waves) + [0.0] * max(
            0, max(noll, default=0) - len(self.objective_zernike_waves)
        )
        for j, v in zip(noll, coefficients, strict=True):
            c[j - 1] = round(float(v), 4)
        return self.model_copy(update={"objective_zernike_waves": tuple(c)})

    def summary(self) -> str:
        """One line for people: the objective's terms and how many lenslets differ, or 'none'."""
        if self.is_nominal:
            return "aberrations: none (the nominal optics)"
        parts = []
        terms = [f"Z{j} {c:+.3f}" for j, c in enumerate(self.objective_zernike_waves, start=1) if c]
        if terms:
            parts.append(f"objective {', '.join(terms)} waves rms")
        odd = [t for t in self.lenslets if not t.is_nominal]
        if odd:
            worst = max(abs(t.defocus_waves) for t in odd)
            shift = max(abs(complex(*t.offset_um)) for t in odd)
            scale = max(abs(t.radius_scale - 1) for t in odd)
            parts.append(
                f"{len(odd)} {'lenslet differs' if len(odd) == 1 else 'lenslets differ'} (defocus up to {worst:.3f} "
                f"waves, centre up to {shift:.2f} µm, "
                f"radius up to {100 * scale:.1f} %)"
            )
        if self.condenser_offset_na != (0.0, 0.0):
            cx, cy = self.condenser_offset_na
            parts.append(f"condenser off axis by ({cx:+.4f}, {cy:+.4f}) NA")
        return "aberrations: " + "; ".join(parts)
