"""Objects linked over frames into tracks: the nearest centroids, one to one, within a step.

Between consecutive measured frames the objects are paired by the smallest total centroid
distance (``scipy.optimize.linear_sum_assignment``) among the pairs at most ``max_step_um`` apart;
an object left without a partner starts a new track, and a track whose object is not found in a
frame ends (no gap closing).
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment

from napari_ssdpc.errors import SsdpcError

__all__ = ["DEFAULT_MAX_STEP_UM", "link_tracks"]

#: The farthest an object's centroid may move between two frames and keep its track, µm.
DEFAULT_MAX_STEP_UM = 10.0


def link_tracks(frames: list[list[dict]], max_step_um: float = DEFAULT_MAX_STEP_UM) -> list[list[dict]]:
    """Give every object of every frame a track id.

    Parameters
    ----------
    frames : list of list of dict
        Per measured frame, in time order, its objects; each has ``x_um``, ``y_um``, ``z_um`` (µm).
    max_step_um : float
        The largest centroid displacement between consecutive frames that continues a track, µm.

    Returns
    -------
    list of list of dict
        The same objects (copies) with ``track`` (int, from 1 in order of appearance).
    """
    if not (np.isfinite(max_step_um) and max_step_um > 0):
        raise SsdpcError(f"max step {max_step_um} µm: give a distance > 0 µm")
    out: list[list[dict]] = []
    previous: list[dict] = []
    next_id = 1
    for objects in frames:
        current = [{k: v for k, v in o.items() if k != "track"} for o in objects]
        if previous and current:
            a = np.array([[o["x_um"], o["y_um"], o["z_um"]] for o in previous], dtype=np.float64)
            b = np.array([[o["x_um"], o["y_um"], o["z_um"]] for o in current], dtype=np.float64)
            dist = np.linalg.norm(a[:, None, :] - b[None, :, :], axis=-1)
            cost = np.where(dist <= max_step_um, dist, 1e9)  # pairs too far apart are never chosen
            for i, j in zip(*linear_sum_assignment(cost)):
                if dist[i, j] <= max_step_um:
                    current[j]["track"] = previous[i]["track"]
        for o in current:
            if "track" not in o:
                o["track"] = next_id
                next_id += 1
        out.append(current)
        previous = current
    return out
