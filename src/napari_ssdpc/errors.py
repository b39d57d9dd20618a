"""Error, warning and cancel types shared by the whole package.

Every message is one line that names the fix. The CLI and the napari widgets show
``str(error)`` as it is, never a traceback.
"""


class SsdpcError(ValueError):
    """Bad input or an impossible request. The message says what to change."""


class SsdpcWarning(UserWarning):
    """A result is computed, but the user should know that it may be poor."""


class Cancelled(Exception):
    """The user asked to stop a running job. Not an input error: nothing needs fixing."""
