"""A picture of a calibration: the frame with every EI circle, its label and deviation."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from napari_ssdpc._version import SOFTWARE
from napari_ssdpc.calibration.frame import validated
from napari_ssdpc.calibration.result import Calibration
from napari_ssdpc.files import atomic_write


def overlay_png(frame, calibration: Calibration, path, *, dpi: int = 110) -> Path:
    """PNG of the frame with the detected EI circles, (row, col) labels, each measured centre's
    deviation from the lattice (cyan arrows, magnified) and the optical axis (red +), cropped to
    the lenslets in the pupil. Written atomically.

    Parameters
    ----------
    frame : array_like, (H, W)
        The frame calibrated on.
    calibration : Calibration
    path : str or Path
        The PNG to write.
    dpi : int
        Resolution of the figure.

    Returns
    -------
    Path
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.patches import Circle

    label_box = dict(boxstyle="round,pad=0.15", fc="black", alpha=0.6, lw=0)
    img = validated(frame)
    cal = calibration
    g = cal.grid
    fig = Figure(figsize=(8, 8))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot(1, 1, 1)
    lo, hi = np.percentile(img, [1, 99.8])
    ax.imshow(img, cmap="gray", vmin=lo, vmax=hi, interpolation="nearest")
    c = cal.centres_px
    for ln, (cx, cy) in zip(cal.lenslets, c):
        col = "lime" if ln.fraction >= 0.5 else "orange"
        ax.add_patch(Circle((cx, cy), cal.ei_radius_px, fill=False, color=col, lw=0.8))
        ax.plot(cx, cy, ".", color=col, ms=2)
        ax.text(
            cx,
            cy - 0.35 * cal.ei_radius_px,
            f"({ln.row},{ln.col})",
            color=col,
            ha="center",
            va="center",
            fontsize=7,
            bbox=label_box,
        )
    start, arrow, gain = cal.deviation_arrows()
    if len(start):  # each EI centre's deviation from the lattice, magnified
        ax.quiver(*start.T, *arrow.T, angles="xy", scale_units="xy", scale=1, color="cyan", width=0.003)
    ax.plot(*g.axis_px, "r+", ms=18, mew=2)
    r_pupil = cal.optics.pupil_radius_mla_um / cal.optics.pitch_um * g.pitch_px
    ax.add_patch(Circle(g.axis_px, r_pupil, fill=False, color="red", lw=0.8, ls="--"))
    m = cal.ei_radius_px * 1.3
    ax.set_xlim(min(c[:, 0].min(), g.axis_px[0] - r_pupil) - m, max(c[:, 0].max(), g.axis_px[0] + r_pupil) + m)
    ax.set_ylim(max(c[:, 1].max(), g.axis_px[1] + r_pupil) + m, min(c[:, 1].min(), g.axis_px[1] - r_pupil) - m)
    ax.set_title(
        f"{cal.kind} frame: axis ({g.axis_px[0]:.2f}, {g.axis_px[1]:.2f}) px, pitch {g.pitch_px:.3f} px, "
        f"rotation {g.rotation_deg:+.3f}°, lattice rms {cal.residual_px:.3f} px\ngreen: ≥50% inside pupil, "
        f"orange: edge; red: optical axis and pupil; cyan: deviation from the lattice x {gain:.0f}",
        fontsize=9,
    )
    ax.set_xlabel("x (px)")
    ax.set_ylabel("y (px)")
    fig.tight_layout()
    path = Path(path)
    with atomic_write(path) as tmp:
        fig.savefig(tmp, dpi=dpi, format="png", metadata={"Software": SOFTWARE})
    return path
