"""The ssdpc command: :func:`napari_ssdpc.cli.main.main`, entered through :func:`run` (which loads
it inside the Ctrl-C guard)."""

from napari_ssdpc.cli.entry import run

__all__ = ["run"]
