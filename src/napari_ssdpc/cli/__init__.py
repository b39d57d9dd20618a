"""The ssdpc command: :func:`napari_ssdpc.cli.main.main`, entered through
:func:`napari_ssdpc.cli.entry.run` (which loads it inside the Ctrl-C guard)."""

__all__: list[str] = []
