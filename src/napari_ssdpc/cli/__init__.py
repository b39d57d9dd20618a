"""The ssdpc command."""

from napari_ssdpc.cli.main import main

__all__ = ["main"]
