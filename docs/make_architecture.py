"""Draw docs/images/architecture.png: the layers of napari-ssdpc and the path of one frame.

Run: python docs/make_architecture.py
"""

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
from matplotlib.patches import FancyArrowPatch, FancyBboxPatch

OUT = Path(__file__).parent / "images" / "architecture.png"

# (name, what it holds, row, column span) from the bottom layer up
LAYERS = [
    ("settings/", "Optics, ReconstructionSettings (one section per\nmethod), OutputSettings, RunConfig", 0, (0, 3)),
    (
        "physics/",
        "design, lattice, lenslet geometry, pupils, waves, PSF (Eq. 6),\n"
        "WOTFs (Eqs. 2-4), multislice model of the views",
        1,
        (0, 3),
    ),
    ("calibration/", "EI disks, lattice, optical axis,\ncalibrate(), extract_views()", 2, (0, 1.45)),
    (
        "reconstruction/",
        "Reconstructor; Measurements (views once), stacks;\n"
        "methods/ registry: tv | wotf | rl | multislice; nonlinear solver",
        2,
        (1.55, 3),
    ),
    ("simulation/", "phantoms, multislice,\nlenslet imaging, camera", 2.9, (0, 0.72)),
    ("io/", "StoredFrames, OME-TIFF,\nOME-Zarr store", 2.9, (0.77, 1.49)),
    ("analysis/", "objects: dry mass, volume,\nRI, centroid; tracks", 2.9, (1.54, 2.26)),
    ("pipeline/", "Job, sources, sinks,\nframe loop, Dask", 2.9, (2.31, 3)),
    ("cli/", "ssdpc design | calibrate | simulate |\nreconstruct | measure | bench | demo", 3.8, (0, 0.95)),
    ("_napari/", "readers, writer, sample data,\nsession (one Job), widgets", 3.8, (1.025, 1.975)),
    ("validation/", "metrics, cases, figures,\ndemo, reference path, bench", 3.8, (2.05, 3)),
]
STEPS = [
    ("RunConfig + calibration + flat", "pipeline.job.Job: Reconstructor built once"),
    ("frame source", "pipeline.sources (StoredFrames, LiveFrames)"),
    ("checked views (K, h, w), once", "Measurements: contrast.ViewContrast"),
    ("phase per slab (Z, y, x)", "reconstruction.methods: tv | wotf | rl | multislice"),
    ("Δn, RI volume, checked", "frame_result.Result, checks.check_result"),
    ("sink", "pipeline.sinks: memory | OME-TIFF | OME-Zarr"),
]


def main() -> None:
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(14, 6.5), gridspec_kw={"width_ratios": [1.35, 1]})
    for a in (ax, bx):
        a.set_axis_off()
    ax.set_xlim(-0.05, 3.05)
    ax.set_ylim(-0.2, 4.7)
    ax.set_title("Layers: dependencies point down only", fontsize=12)
    for name, what, row, (x0, x1) in LAYERS:
        ax.add_patch(FancyBboxPatch((x0, row), x1 - x0, 0.72, boxstyle="round,pad=0.02", fc="#e8f0fb", ec="#3465a4"))
        ax.text((x0 + x1) / 2, row + 0.52, name, ha="center", va="center", fontsize=10, weight="bold")
        ax.text((x0 + x1) / 2, row + 0.22, what, ha="center", va="center", fontsize=7.5)
    ax.text(
        1.5,
        4.6,
        "errors.py · files.py · progress.py · statistics.py · backend.py (NumPy | CuPy, the one FFT entry): "
        "used by every layer",
        ha="center",
        fontsize=8,
    )
    bx.set_xlim(0, 1)
    bx.set_ylim(-0.5, len(STEPS))
    bx.set_title("The frame loop (pipeline.run.Pipeline)", fontsize=12)
    for i, (what, where) in enumerate(STEPS):
        y = len(STEPS) - 1 - i
        bx.add_patch(FancyBboxPatch((0.1, y), 0.8, 0.6, boxstyle="round,pad=0.02", fc="#fdf3e1", ec="#c17d11"))
        bx.text(0.5, y + 0.4, what, ha="center", va="center", fontsize=10, weight="bold")
        bx.text(0.5, y + 0.15, where, ha="center", va="center", fontsize=8, family="monospace")
        if i:
            bx.add_patch(FancyArrowPatch((0.5, y + 1.0), (0.5, y + 0.62), arrowstyle="-|>", mutation_scale=14))
    fig.tight_layout()
    OUT.parent.mkdir(exist_ok=True)
    fig.savefig(OUT, dpi=110)
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
