"""stiff: joint stiffness identification, diagnosis and deflection compensation for
industrial robots. numpy-first API over the C ABI (libstiff_c); SI units (m, rad, N, N*m)."""
from .api import (Dataset, Fit, Model, Robot, describe_effect, effects, identify,
                  identify_defaults, library_version, noise_defaults, predict, random_design,
                  simulate)
from .fmu import export_fmu, fmu_defaults
from .plan import Plan, criteria, evaluate_criteria, plan, plan_defaults
from .diagnose import Diagnosis, diagnose, diagnose_defaults
from .compensate import compensate_path, inverse_kinematics, read_path  # noqa: F401
from . import data  # noqa: F401  (built-in files by name: stiff.data.find, stiff.data.names)
from .errors import (CancelledError, InvalidArgumentError, NumericalError, ParseError,
                     StiffError, StiffIOError)

__version__ = "0.1.0"

__all__ = ["Robot", "Dataset", "Fit", "Model", "identify", "simulate", "random_design", "predict",
           "effects", "describe_effect", "diagnose", "Diagnosis", "export_fmu", "plan", "plan_defaults",
           "identify_defaults", "noise_defaults", "diagnose_defaults", "fmu_defaults", "Plan", "criteria", "evaluate_criteria", "library_version", "StiffError", "ParseError",
           "InvalidArgumentError", "NumericalError", "CancelledError", "StiffIOError",
           "data", "__version__"]
