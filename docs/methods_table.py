"""The side-by-side table of docs/validation.md from docs/methods.json and docs/methods_na0.25.json.

python docs/methods_table.py
"""

from __future__ import annotations

import json
from pathlib import Path

HERE = Path(__file__).parent
FILES = {"0.25": HERE / "methods_na0.25.json", "0.3": HERE / "methods.json"}
METHODS = ("wotf", "tv")


BEAD_ROWS = (  # label, value of one bead, format
    ("peak Δn / true", lambda b: b["dn_peak"] / b["dn_true"], ".2f"),
    ("centroid depth error (µm)", lambda b: b["depth_error_um"], "+.1f"),
    ("depth error of the peak (µm)", lambda b: b["peak_depth_error_um"], "+.0f"),
    ("projected phase at the centre / true", lambda b: b["phase_centre_ratio"], ".2f"),
    ("projected phase over the footprint / true", lambda b: b["phase_footprint_ratio"], ".2f"),
    ("lateral x axial FWHM (µm)", lambda b: f"{b['fwhm_x_um']:.1f} x {b['fwhm_z_um']:.1f}", ""),
)
CELL_ROWS = (
    ("RI in the nucleus (blurred truth)", lambda r: f"{r['ri_nucleus']:.4f} ({r['ri_nucleus_blurred_truth']:.4f})", ""),
    ("centroid depth error (µm)", lambda r: r["depth_error_um"], "+.1f"),
)
COMMON_ROWS = (
    ("correlation with the truth blurred to (R_z, R_xy)", lambda r: r["correlation_blurred"], ".3f"),
    ("Σ Δn within 50 µm of the axis / true", lambda r: r["optical_volume_ratio"], ".2f"),
    ("seconds per frame (2 cores)", lambda r: r["seconds"], ".1f"),
)


def table(data: dict[str, dict]) -> str:
    """Markdown: one row per case and metric, one column per condenser NA and method."""
    cols = [(na, m) for na in data for m in METHODS]
    lines = [
        "| case | metric | " + " | ".join(f"NA {na} `{m}`" for na, m in cols) + " |",
        "| --- | --- | " + " | ".join("---" for _ in cols) + " |",
    ]
    for case in next(iter(data.values())):
        beads = "beads" in data[next(iter(data))][case]["tv"]
        rows = [(label, fn, fmt, beads) for label, fn, fmt in (BEAD_ROWS if beads else CELL_ROWS)]
        rows += [(label, fn, fmt, False) for label, fn, fmt in COMMON_ROWS]
        for label, fn, fmt, per_bead in rows:
            cells = []
            for na, m in cols:
                r = data[na][case][m]
                cells.append(" / ".join(format(fn(x), fmt) for x in (r["beads"] if per_bead else [r])))
            lines.append(f"| {case} | {label} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main():
    data = {na: json.loads(path.read_text()) for na, path in FILES.items()}
    print(table(data))


if __name__ == "__main__":
    main()
