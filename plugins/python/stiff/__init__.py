"""stiff: joint stiffness identification, diagnosis and deflection compensation for
industrial robots. numpy-first API over the C ABI (libstiff_c); SI units (m, rad, N, N*m)."""
from .api import (Dataset, Fit, Model, Robot, describe_effect, effects, identify,
                  library_version, predict, random_design, simulate)
from .errors import (CancelledError, InvalidArgumentError, NumericalError, ParseError,
                     StiffError, StiffIOError)

__version__ = "0.1.0"

__all__ = ["Robot", "Dataset", "Fit", "Model", "identify", "simulate", "random_design", "predict",
           "effects", "describe_effect", "library_version", "StiffError", "ParseError",
           "InvalidArgumentError", "NumericalError", "CancelledError", "StiffIOError",
           "__version__"]
