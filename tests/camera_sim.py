"""A Micro-Manager core with pymmcore-plus's pure-Python camera device (no hardware, no Micro-Manager
install) serving given frames, for the tests of the camera source."""

from __future__ import annotations

import time

import numpy as np
from pymmcore_plus.experimental import unicore


class SimulatedCamera(unicore.SimpleCameraDevice):
    """Serves the given frames in turn, one every 15 ms (a 67 Hz camera; the paper records at 74 Hz)."""

    def __init__(self, frames):
        super().__init__()
        self.frames, self.k, self.exposure = frames, 0, 10.0

    def sensor_shape(self):
        return self.frames.shape[1:]

    def dtype(self):
        return self.frames.dtype

    def get_exposure(self):
        return self.exposure

    def set_exposure(self, value):
        self.exposure = value

    def snap(self, buffer):
        time.sleep(0.015)
        buffer[:] = self.frames[self.k % len(self.frames)]
        self.k += 1
        return {}


def core_with(frames):
    """A core whose camera serves ``frames`` ((n, H, W)) in turn."""
    core = unicore.UniMMCore()
    core.loadPyDevice("Camera", SimulatedCamera(frames))
    core.initializeDevice("Camera")
    core.setCameraDevice("Camera")
    core.setCircularBufferMemoryFootprint(1024)  # MB: the core never loses a frame of these tests
    return core


def series(shape, n):
    """n frames of constant value k + 1 (frame k)."""
    return np.stack([np.full(shape, k + 1, np.uint16) for k in range(n)])
