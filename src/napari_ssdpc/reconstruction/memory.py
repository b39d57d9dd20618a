"""The memory a reconstruction will take, against the free memory: refused before anything large
is allocated (a z range of 1e-9 µm steps once asked for 149 GiB)."""

from __future__ import annotations

import math
import os

from napari_ssdpc.errors import SsdpcError

__all__ = ["available_memory", "check_memory", "estimate_memory"]


def available_memory() -> int:
    """Free memory in bytes (MemAvailable), or the physical memory where that is unknown."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"))
    except (ValueError, OSError, AttributeError):
        return 1 << 40


def estimate_memory(optics, cal, settings, stacks: bool) -> dict:
    """Bytes the Reconstructor's operators and one frame's outputs will take (an upper estimate).

    Parameters
    ----------
    optics : Optics
    cal : Calibration
    settings : ReconstructionSettings
    stacks : bool
        Whether the Richardson-Lucy stacks are computed.

    Returns
    -------
    dict
        ``planes``, ``lenslets``, ``operators`` and ``outputs`` (bytes) and ``total``.
    """
    planes = settings.planes
    side = 2 * math.ceil(cal.ei_radius_px) + 1
    view = side * side  # pixels per view
    k = max(1, len(cal.lenslets))
    with_rl = stacks
    # (K x Z x band) complex64 operators: WOTF once, RL per half (each lenslet in two halves)
    tv = settings.method in ("tv", "multislice")  # the multislice method starts from the tv solution
    ops = k * planes * (view // 2) * 8 * ((settings.method == "wotf" or tv) + 2 * with_rl)
    if tv:  # its operator on the padded z grid, and ~12 ADMM work arrays
        padded = planes + 2 * math.ceil(25.0 / settings.dz_um)
        ops += k * padded * (view // 2) * 8 + 12 * padded * view * 8
    if with_rl:  # per half and plane: padded (~1.7x view side) support and normalisation arrays
        ops += 4 * planes * int(3 * view) * 12
    outputs = planes * view * 4 * (3 + 6 * with_rl)  # ri, delta_n, phase (+ stacks, dpc, absorption)
    return {"planes": planes, "lenslets": k, "operators": ops, "outputs": outputs, "total": ops + outputs}


def check_memory(optics, cal, settings, stacks: bool, available: int | None = None) -> dict:
    """Refuse a reconstruction whose operators and outputs do not fit in the free memory.

    Parameters
    ----------
    optics, cal, settings, stacks
        As for :func:`estimate_memory`.
    available : int, optional
        Free bytes; default :func:`available_memory`.

    Returns
    -------
    dict
        The estimate.
    """
    est = estimate_memory(optics, cal, settings, stacks)
    free = available_memory() if available is None else int(available)
    if est["total"] > 0.8 * free:
        gib = 1 << 30
        factor = math.ceil(est["total"] / (0.8 * free))
        raise SsdpcError(
            f"this reconstruction needs about {est['total'] / gib:.1f} GiB (operators {est['operators'] / gib:.1f} "
            f"GiB for up to {est['lenslets']} lenslets x {est['planes']} planes, outputs {est['outputs'] / gib:.1f} "
            f"GiB) but {free / gib:.1f} GiB are free; narrow --z or take a larger --dz "
            f"(e.g. --dz {settings.dz_um * factor:g})"
        )
    return est
