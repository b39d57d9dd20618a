"""Physics of the Fourier light-field microscope: design calculator, lattice geometry, pupils,
the wave-optics PSF (paper Eq. 6) and the weak-object transfer functions (paper Eqs. 2-4)."""

from napari_ssdpc.physics.design import design, design_table, design_warnings
from napari_ssdpc.physics.dpc_transfer import dpc_transfer_functions
from napari_ssdpc.physics.lattice import Grid
from napari_ssdpc.physics.psf import LensletPSF, reference_psf
from napari_ssdpc.physics.pupil import axial_frequency, eta, mean_tilt, soft_disk, subaperture_pupil
from napari_ssdpc.physics.transfer import (
    lenslet_case,
    lenslet_transfer_functions,
    weak_object_transfer_functions,
)

__all__ = [
    "Grid",
    "LensletPSF",
    "axial_frequency",
    "design",
    "design_table",
    "design_warnings",
    "dpc_transfer_functions",
    "eta",
    "lenslet_case",
    "lenslet_transfer_functions",
    "mean_tilt",
    "reference_psf",
    "soft_disk",
    "subaperture_pupil",
    "weak_object_transfer_functions",
]
