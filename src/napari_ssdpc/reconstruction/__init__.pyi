from .bead import Bead
from .beads import fit_beads, measure_beads
from .condenser_fit import CondenserFit, fit_condenser
from .frame_result import Result
from .methods import METHODS, method_class
from .methods.base import PhaseMethod, Setup, Solution
from .optics_fit import OpticsFit, fit_optics
from .reconstructor import Reconstructor
from .regularised import TvInversion
from .tv_report import TvReport
from .wotf import WotfInversion

__all__ = [
    "METHODS",
    "OpticsFit",
    "Bead",
    "CondenserFit",
    "PhaseMethod",
    "Reconstructor",
    "Result",
    "Setup",
    "Solution",
    "TvInversion",
    "TvReport",
    "WotfInversion",
    "fit_beads",
    "fit_condenser",
    "fit_optics",
    "measure_beads",
    "method_class",
]
