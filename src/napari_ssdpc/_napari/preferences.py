"""Files that open without questions: napari's reader preferences for this plugin's own file names.

napari asks "Choose reader" whenever two plugins' file-name patterns match, and its builtin reader
matches every ``*.tif`` and ``*.zarr`` (and every folder). For the names that are this plugin's
own, the plugin records itself as the preferred reader, exactly as ticking "remember" in that
dialog does (napari's settings, ``plugins.extension2reader``); a preference the user set is never
changed. Recorded when the plugin is first used in a napari session (npe2 ``on_activate``) and when
its dock opens.
"""

from __future__ import annotations

__all__ = ["OWN_PATTERNS", "PLUGIN", "activate", "prefer_own_readers"]

PLUGIN = "napari-ssdpc"
#: napari's patterns (fnmatch on the full path; a folder's path ends in '/') for this plugin's own
#: file names: results ``NAME.ssdpc.ome.tif`` / ``NAME.ssdpc.zarr`` and raw frames ``NAME.lf.tif``.
OWN_PATTERNS = (
    "*.ssdpc.ome.tif",
    "*.ssdpc.ome.tiff",
    "*.ssdpc.zarr",
    "*.ssdpc.zarr/",
    "*.lf.tif",
    "*.lf.tiff",
    "*_lf.tif",
    "*_lf.tiff",
)


def prefer_own_readers() -> list[str]:
    """Make this plugin napari's reader for :data:`OWN_PATTERNS` where no preference is set.

    Returns
    -------
    list of str
        The patterns added (empty when all were set already, or napari's settings are unavailable).
    """
    try:
        from napari.settings import get_settings

        plugins = get_settings().plugins
    except Exception:  # napari absent or its settings unreadable: nothing to prefer
        return []
    current = dict(plugins.extension2reader)
    added = [p for p in OWN_PATTERNS if p not in current]
    if added:
        plugins.extension2reader = {**current, **dict.fromkeys(added, PLUGIN)}
    return added


def activate(_context=None) -> None:
    """npe2's ``on_activate``: called the first time a contribution of the plugin is used.

    Parameters
    ----------
    _context : npe2 PluginContext, optional
    """
    prefer_own_readers()
