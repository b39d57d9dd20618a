from .design import design, design_table, design_warnings
from .dpc_transfer import dpc_transfer_functions
from .lattice import Grid, lenslet_case
from .psf import LensletPSF
from .psf_reference import reference_psf
from .pupil import Pupil, axial_frequency, eta, mean_tilt, soft_disk, subaperture_pupil
from .transfer import (
    lenslet_transfer_functions,
    weak_object_transfer_functions,
)
from .zernike import noll_to_nm, zernike, zernike_sum

__all__ = [
    "Grid",
    "LensletPSF",
    "Pupil",
    "axial_frequency",
    "design",
    "design_table",
    "design_warnings",
    "dpc_transfer_functions",
    "eta",
    "lenslet_case",
    "lenslet_transfer_functions",
    "mean_tilt",
    "noll_to_nm",
    "reference_psf",
    "soft_disk",
    "subaperture_pupil",
    "weak_object_transfer_functions",
    "zernike",
    "zernike_sum",
]
