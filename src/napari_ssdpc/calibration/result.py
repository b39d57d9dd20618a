"""The calibration result: the per-lenslet table, its versioned JSON, and the EI views.

A ``Calibration`` is what ``calibrate`` measured on one frame: the lattice (as a
``Grid``), the optical axis, and one row per lenslet with its own measured EI centre,
its deviation from the lattice, u_k and its brightness. ``Views`` is a stack of EIs
resampled on the object grid (``views.extract_views``).
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from napari_ssdpc.calibration.frame import validated
from napari_ssdpc.errors import SsdpcError
from napari_ssdpc.files import atomic_write
from napari_ssdpc.physics.lattice import Grid, xy_pair
from napari_ssdpc.settings.lenslets import Lenslet
from napari_ssdpc.settings.optics import Optics

CALIBRATION_FORMAT = "napari-ssdpc-calibration"
CALIBRATION_VERSION = 1


def content_checksum(d: dict) -> str:
    """SHA-256 of a calibration's values (every key but ``checksum``), in canonical JSON.

    Parameters
    ----------
    d : dict
        As :meth:`Calibration.to_dict` gives it, or as read back from its file.

    Returns
    -------
    str
        Hex digest.
    """
    body = {k: v for k, v in d.items() if k != "checksum"}
    return hashlib.sha256(json.dumps(body, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


# ---------------------------------------------------------------- data classes
@dataclass(eq=False)
class Calibration:
    """Lenslet grid measured on one frame.

    Attributes
    ----------
    grid : Grid
        Optical axis, the lattice vertex nearest it, mean pitch and rotation: the lattice
        as a similarity (labels, the EI orientation, the scale).
    ei_radius_px : float
        Median radius of the EI disks, px.
    lenslets : list of Lenslet
        One per lenslet overlapping the pupil; ``a_um``, ``u`` and ``fraction`` come from
        the lenslet's own measured centre.
    centres_px : ndarray (K, 2)
        EI centre (x, y) px per lenslet: measured where ``measured``, else the affine
        lattice's position.
    brightness : ndarray (K,)
        EI brightness relative to a fully lit lenslet (≈ ``fraction`` on a white frame;
        NaN where the EI leaves the frame).
    residual_px : float
        rms deviation of the measured EI centres from the fitted affine lattice, px.
    axis_rms : float
        rms of the brightness-pattern fit that gave the axis, relative to full brightness
        (NaN where the axis was given or assumed: ``kind_evidence["axis"]``).
    kind : str
        "white", "flat" or "sample"; ``kind_evidence`` says why and how sure.
    rim_defocus_waves : float or None
        The views' defocus the white frame's elemental-image rims show (the views nearest the axis,
        waves at the sub-aperture's edge; :func:`~napari_ssdpc.calibration.view_focus.rim_defocus`);
        None where the frame was not a white frame.
    optics_fit : dict
        What `ssdpc fit-optics` fitted into ``optics`` from the user's frames (each part's terms,
        uncertainties and misfit; empty for a calibration of the nominal optics).
    deviation_px : ndarray (K, 2)
        Measured centre minus lattice position, px (NaN where not measured).
    measured : ndarray (K,) bool
        Whether the lenslet's centre was measured on its own rim.
    shear_deg, aspect : float
        Angle between the two lattice axes minus 90°, ratio of their lengths minus 1.
    """

    grid: Grid
    ei_radius_px: float
    optics: Optics
    frame_shape: tuple[int, int]
    lenslets: list[Lenslet]
    centres_px: np.ndarray
    brightness: np.ndarray
    residual_px: float
    axis_rms: float
    kind: str
    n_fitted: int = 0
    version: int = CALIBRATION_VERSION
    deviation_px: np.ndarray | None = None
    measured: np.ndarray | None = None
    shear_deg: float = 0.0
    aspect: float = 0.0
    kind_evidence: dict = field(default_factory=dict)
    optics_fit: dict = field(default_factory=dict)
    rim_defocus_waves: float | None = None

    def __post_init__(self) -> None:
        k = len(self.lenslets)
        if self.deviation_px is None:
            self.deviation_px = np.full((k, 2), np.nan)
        if self.measured is None:
            self.measured = np.isfinite(self.deviation_px).all(axis=1)

    @property
    def max_deviation_px(self) -> float:
        """Largest distance of a measured EI centre from the lattice, px (0 when none)."""
        d = np.hypot(*np.asarray(self.deviation_px, float).T)
        d = d[np.isfinite(d)]
        return float(d.max()) if d.size else 0.0

    def deviation_arrows(self) -> tuple[np.ndarray, np.ndarray, float]:
        """Arrows that show each measured EI centre's deviation from the lattice, magnified.

        Returns
        -------
        start : ndarray, (M, 2)
            Lattice positions (x, y) of the measured lenslets, px.
        arrow : ndarray, (M, 2)
            Their deviations (x, y) times ``gain``, px.
        gain : float
            Magnification: the longest arrow is a third of the EI radius (1 to 500).
        """
        dev = np.asarray(self.deviation_px, float)
        ok = np.isfinite(dev).all(axis=1)
        start = np.asarray(self.centres_px, float)[ok] - dev[ok]
        gain = float(np.clip(self.ei_radius_px / 3 / max(self.max_deviation_px, 1e-9), 1.0, 500.0))
        return start, dev[ok] * gain, gain

    # ------------------------------------------------------------- table
    @property
    def table(self) -> list[dict]:
        """One dict per lenslet: row, col, centre_px, measured, deviation_px, a_um, u,
        fraction, halves, brightness."""
        out = []
        dev = np.asarray(self.deviation_px, float)
        for ln, c, b, d in zip(self.lenslets, self.centres_px, self.brightness, dev):
            out.append(
                {
                    "row": ln.row,
                    "col": ln.col,
                    "centre_px": [float(c[0]), float(c[1])],
                    "measured": bool(np.isfinite(d).all()),
                    "deviation_px": [float(d[0]), float(d[1])] if np.isfinite(d).all() else None,
                    "a_um": [float(v) for v in ln.a_um],
                    "u": [float(v) for v in ln.u],
                    "fraction": float(ln.fraction),
                    "halves": list(ln.halves),
                    "brightness": None if not np.isfinite(b) else float(b),
                }
            )
        return out

    def check_frame(self, frame, name="frame") -> np.ndarray:
        """Validate a frame against this calibration; return it as float32.

        Parameters
        ----------
        frame : array_like, (H, W)
            Camera units.
        name : str
            How messages name it.

        Returns
        -------
        ndarray, float32, (H, W)
        """
        img = validated(frame, name)
        if img.shape != tuple(self.frame_shape):
            raise SsdpcError(
                f"{name}: shape {img.shape} differs from the calibration's {tuple(self.frame_shape)}; "
                "use frames from the same camera ROI and binning, or calibrate on a white frame "
                "of this shape"
            )
        return img

    # ------------------------------------------------------------- JSON
    def to_dict(self) -> dict:
        """The calibration as plain values (the versioned JSON).

        Returns
        -------
        dict
            JSON-ready: format and version, grid, EI radius (px), kind, residual, the lenslet table
            and the checksum of them all.
        """
        d = {
            "format": CALIBRATION_FORMAT,
            "version": self.version,
            "kind": self.kind,
            "frame_shape": [int(v) for v in self.frame_shape],
            "axis_px": [float(v) for v in self.grid.axis_px],
            "pitch_px": float(self.grid.pitch_px),
            "rotation_deg": float(self.grid.rotation_deg),
            "ei_radius_px": float(self.ei_radius_px),
            "residual_px": float(self.residual_px),
            "axis_rms": float(self.axis_rms) if np.isfinite(self.axis_rms) else None,  # None: not measured
            "n_fitted": int(self.n_fitted),
            "max_deviation_px": self.max_deviation_px,
            "shear_deg": float(self.shear_deg),
            "aspect": float(self.aspect),
            "kind_evidence": dict(self.kind_evidence),
            "grid": self.grid.to_dict(),
            "lenslets": self.table,
            "optics": self.optics.to_dict(),
        }
        if self.optics_fit:  # a calibration of the nominal optics keeps its old form and checksum
            d["optics_fit"] = self.optics_fit
        if self.rim_defocus_waves is not None:  # so does one from before the rims were measured
            d["rim_defocus_waves"] = float(self.rim_defocus_waves)
        return {**d, "checksum": content_checksum(d)}

    @classmethod
    def from_dict(cls, d: dict, source: str = "calibration", verify: bool = True) -> Calibration:
        """A calibration from its JSON values; a one-line error names what is wrong.

        Parameters
        ----------
        d : dict
            As written by :meth:`to_dict`.
        source : str
            How messages name where it came from.
        verify : bool
            Check the content against its ``checksum`` (files from before the checksum have none).

        Returns
        -------
        Calibration
        """
        if not isinstance(d, dict) or d.get("format") != CALIBRATION_FORMAT:
            raise SsdpcError(f"{source}: not a napari-ssdpc calibration file; run `ssdpc calibrate` on a white frame")
        if d.get("version") != CALIBRATION_VERSION:
            raise SsdpcError(
                f"{source}: calibration version {d.get('version')!r} is not supported "
                f"(this software reads version {CALIBRATION_VERSION}); re-run `ssdpc calibrate`"
            )
        try:
            optics = Optics.from_dict(d["optics"], source=f"{source} optics")
            grid = Grid.from_dict(d["grid"])
            rows = d["lenslets"]
            lenslets = [
                Lenslet(
                    int(r["row"]),
                    int(r["col"]),
                    xy_pair(r["a_um"]),
                    xy_pair(r["u"]),
                    float(r["fraction"]),
                )
                for r in rows
            ]
            centres = np.array([r["centre_px"] for r in rows], dtype=float).reshape(-1, 2)
            bright = np.array([np.nan if r.get("brightness") is None else r["brightness"] for r in rows], float)
            dev = np.array([r.get("deviation_px") or [np.nan, np.nan] for r in rows], float).reshape(-1, 2)
            cal = cls(
                grid=grid,
                ei_radius_px=float(d["ei_radius_px"]),
                optics=optics,
                frame_shape=(int(d["frame_shape"][0]), int(d["frame_shape"][1])),
                lenslets=lenslets,
                centres_px=centres,
                brightness=bright,
                residual_px=float(d["residual_px"]),
                axis_rms=float("nan") if d["axis_rms"] is None else float(d["axis_rms"]),
                kind=str(d["kind"]),
                n_fitted=int(d.get("n_fitted", 0)),
                version=int(d["version"]),
                deviation_px=dev,
                shear_deg=float(d.get("shear_deg", 0.0)),
                aspect=float(d.get("aspect", 0.0)),
                kind_evidence=dict(d.get("kind_evidence", {})),
                optics_fit=dict(d.get("optics_fit", {})),
                rim_defocus_waves=None if d.get("rim_defocus_waves") is None else float(d["rim_defocus_waves"]),
            )
        except SsdpcError:
            raise
        except (KeyError, TypeError, ValueError) as e:
            raise SsdpcError(
                f"{source}: corrupt calibration ({type(e).__name__}: {e}); re-run `ssdpc calibrate`"
            ) from None
        if verify and "checksum" in d and d["checksum"] != content_checksum(d):
            raise SsdpcError(
                f"{source}: the calibration was edited after `ssdpc calibrate` wrote it (its checksum does not "
                "match its content); re-run `ssdpc calibrate`, or accept a deliberate edit with "
                "`ssdpc resign-calibration FILE`"
            )
        cal.check_values(source)
        return cal

    def check_values(self, source: str = "calibration") -> None:
        """Refuse values no measurement gives: no lenslets, a pitch, radius or centre that is not a
        finite number in range, a lattice mirrored unlike its optics.

        Parameters
        ----------
        source : str
            How messages name the calibration.

        Raises
        ------
        SsdpcError
            The first impossible value, with the key that holds it.
        """
        h, w = (int(v) for v in self.frame_shape)
        g = self.grid
        lens = self.lenslets
        tables = {
            "centre_px": np.asarray(self.centres_px, float).reshape(-1, 2),
            "u": np.array([ln.u for ln in lens], float).reshape(-1, 2),
            "a_um": np.array([ln.a_um for ln in lens], float).reshape(-1, 2),
        }
        problems = [
            (min(h, w) < 16, "frame_shape", self.frame_shape, "two frame sizes of at least 16 px"),
            (not lens, "lenslets", "[]", "one row per lenslet in the pupil"),
            (not 0 < g.pitch_px < max(h, w), "grid.pitch_px", g.pitch_px, "a finite pitch in px, within the frame"),
            (not 0 < self.ei_radius_px < max(h, w), "ei_radius_px", self.ei_radius_px, "a finite radius in px"),
            (not np.isfinite([*g.axis_px, *g.vertex_px, g.rotation_deg]).all(), "grid", g.axis_px, "finite numbers"),
            ((g.flip_x, g.flip_y) != (self.optics.flip_x, self.optics.flip_y), "grid.flip_x", g.flip_x, "its optics'"),
            (len(self.centres_px) != len(lens), "lenslets", len(lens), "one centre_px per lenslet"),
        ]
        for key, a in tables.items():
            problems.append((not np.isfinite(a).all(), f"lenslets[].{key}", "NaN or inf", "finite numbers"))
        fr = np.array([ln.fraction for ln in lens], float)
        problems.append((not ((fr >= 0) & (fr <= 1)).all(), "lenslets[].fraction", "outside 0 to 1", "0 to 1"))
        for bad, key, value, want in problems:
            if bad:
                raise SsdpcError(
                    f"{source}: {key} is {value}, not {want}: the file is damaged or was edited; re-run "
                    "`ssdpc calibrate` on a white frame"
                )

    def to_json(self, path) -> Path:
        """Write the versioned JSON atomically (a failure never leaves a half file).

        Parameters
        ----------
        path : str or Path

        Returns
        -------
        Path
        """
        path = Path(path)
        text = json.dumps(self.to_dict(), indent=1)
        with atomic_write(path) as tmp:
            tmp.write_text(text)
        return path

    @classmethod
    def from_json(cls, path, verify: bool = True) -> Calibration:
        """Read a calibration JSON written by :meth:`to_json`.

        Parameters
        ----------
        path : str or Path
        verify : bool
            Refuse a file whose content no longer matches its checksum (edited by hand).

        Returns
        -------
        Calibration
        """
        if not isinstance(path, (str, os.PathLike)):
            raise SsdpcError(f"give the calibration file's path, got {type(path).__name__}")
        path = Path(path)
        if not path.is_file():
            raise SsdpcError(f"calibration file not found: {path} (run `ssdpc calibrate WHITE.tif -o {path.name}`)")
        try:
            d = json.loads(path.read_text())
        except (json.JSONDecodeError, UnicodeDecodeError):
            raise SsdpcError(f"{path}: corrupt calibration JSON; re-run `ssdpc calibrate`") from None
        return cls.from_dict(d, source=str(path), verify=verify)
