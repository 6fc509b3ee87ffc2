"""ctypes bindings of stiff.h. The only module that knows C signatures; one _check() maps
status codes to exceptions (as pygit2 does over libgit2)."""
from __future__ import annotations

import ctypes as C
import os
from pathlib import Path

import numpy as np

from .errors import BufferTooSmallError, error_for

_HERE = Path(__file__).resolve().parent


def _find_library() -> Path:
    # Explicit choices first (STIFF_LIBRARY, then STIFF_BUILD_DIR: tests and benchmarks name the
    # build they mean), then the library bundled with the package.
    env = os.environ.get("STIFF_LIBRARY")
    if env:
        return Path(env)
    build = os.environ.get("STIFF_BUILD_DIR")
    if build and (Path(build) / "capi" / "libstiff_c.so").exists():
        return Path(build) / "capi" / "libstiff_c.so"
    bundled = _HERE / "_lib" / "libstiff_c.so"
    if bundled.exists():
        return bundled
    raise ImportError(
        "libstiff_c.so not found: install the package with its bundled library (make build), "
        "or set STIFF_LIBRARY to its path"
    )


LIBRARY_PATH = _find_library()
lib = C.CDLL(str(LIBRARY_PATH))

c_double_p = C.POINTER(C.c_double)
c_size_p = C.POINTER(C.c_size_t)
PROGRESS_FN = C.CFUNCTYPE(C.c_int, C.c_uint32, C.c_double, C.c_void_p)


class NoiseOptions(C.Structure):
    _init_ = "stiff_noise_options_init"
    _fields_ = [
        ("struct_size", C.c_uint32),
        ("tracker_sigma_m", C.c_double),
        ("tracker_ppm", C.c_double),
        ("tracker_position_m", C.c_double * 3),
        ("force_relative", C.c_double),
        ("force_absolute_N", C.c_double),
        ("joint_sigma_rad", C.c_double),
        ("outlier_rate", C.c_double),
        ("outlier_size_m", C.c_double),
        ("seed", C.c_uint64),
    ]


class RobotOptions(C.Structure):
    _init_ = "stiff_robot_options_init"
    _fields_ = [
        ("struct_size", C.c_uint32),
        ("base_link", C.c_char_p),
        ("tip_link", C.c_char_p),
        ("set", C.c_uint32),
        ("measured_point_m", C.c_double * 3),
        ("load_point_m", C.c_double * 3),
        ("tool_mass_kg", C.c_double),
        ("tool_com_m", C.c_double * 3),
    ]


class IdentifyOptions(C.Structure):
    _init_ = "stiff_identify_options_init"
    _fields_ = [
        ("struct_size", C.c_uint32),
        ("model", C.c_char_p),
        ("loss", C.c_char_p),
        ("loss_scale_m", C.c_double),
        ("max_iterations", C.c_uint32),
        ("method", C.c_uint32),
        ("progress", PROGRESS_FN),
        ("progress_user_data", C.c_void_p),
        ("max_relative_se", C.c_double),
        ("start", C.c_void_p),
        ("refit", C.c_char_p),
        ("orientation_length_m", C.c_double),
        ("select_terms", C.c_int32),
    ]


class FitStatistics(C.Structure):
    _fields_ = [
        ("struct_size", C.c_uint32),
        ("measurements", C.c_uint32),
        ("rank", C.c_uint32),
        ("dof", C.c_uint32),
        ("rms_m", C.c_double),
        ("sigma_hat_m", C.c_double),
        ("noise_floor_m", C.c_double),
        ("chi2", C.c_double),
        ("condition_number", C.c_double),
        ("outliers", C.c_uint32),
        ("warnings", C.c_uint32),
        ("oriented_rows", C.c_uint32),
        ("orientation_rms_rad", C.c_double),
        ("orientation_mean_rad", C.c_double),
        ("orientation_max_rad", C.c_double),
        ("orientation_length_m", C.c_double),
        ("model_error_m", C.c_double),
        ("model_error_rad", C.c_double),
    ]


def _proto(name, restype, *argtypes):
    fn = getattr(lib, name)
    fn.restype = restype
    fn.argtypes = list(argtypes)
    return fn


H = C.c_void_p  # opaque handle
HP = C.POINTER(C.c_void_p)
S = C.c_int  # stiff_status

_proto("stiff_version", C.c_uint32)
_proto("stiff_version_string", C.c_char_p)
_proto("stiff_last_error", C.c_char_p)
_proto("stiff_status_name", C.c_char_p, C.c_int)
_proto("stiff_robot_load", S, HP, C.c_char_p)
_proto("stiff_robot_load_with", S, HP, C.c_char_p, C.c_void_p)
_proto("stiff_robot_joint_name", S, C.c_char_p, C.c_size_t, c_size_p, H, C.c_size_t)
_proto("stiff_robot_points", S, c_double_p, c_double_p, c_double_p, c_double_p, H)
_proto("stiff_robot_notes", S, C.c_char_p, C.c_size_t, c_size_p, H)
_proto("stiff_robot_to_yaml", S, C.c_char_p, C.c_size_t, c_size_p, H)
_proto("stiff_robot_destroy", None, H)
_proto("stiff_robot_calibrated", S, HP, H, H)
_proto("stiff_robot_to_urdf", S, C.c_char_p, C.c_size_t, c_size_p, H, c_double_p)
_proto("stiff_result_registration", S, c_double_p, H, C.c_char_p)
_proto("stiff_robot_dof", S, c_size_p, H)
_proto("stiff_robot_name", S, C.c_char_p, C.c_size_t, c_size_p, H)
_proto("stiff_robot_limits", S, c_double_p, c_double_p, C.c_size_t, c_size_p, H)
_proto("stiff_robot_tool_pose", S, c_double_p, H, c_double_p, C.c_size_t)
_proto("stiff_robot_jacobian", S, c_double_p, C.c_size_t, c_size_p, H, c_double_p, C.c_size_t)
_proto("stiff_robot_jacobians", S, c_double_p, C.c_size_t, c_size_p, H, c_double_p, C.c_size_t,
       C.c_size_t)
_proto("stiff_dataset_read_csv", S, HP, H, C.c_char_p)
_proto("stiff_dataset_write_csv", S, H, C.c_char_p)
_proto("stiff_file_write", S, C.c_char_p, C.c_void_p, C.c_size_t)
_proto("stiff_dataset_create", S, HP, C.c_size_t, C.c_size_t, c_double_p, c_double_p, c_double_p,
       c_double_p, c_double_p)
_proto("stiff_dataset_destroy", None, H)
_proto("stiff_dataset_size", S, c_size_p, c_size_p, H)
_proto("stiff_dataset_has", S, C.POINTER(C.c_int), H, C.c_int)
_proto("stiff_dataset_get", S, c_double_p, C.c_size_t, c_size_p, H, C.c_int)
_proto("stiff_dataset_set_displacement", S, H, c_double_p, C.c_size_t)
_proto("stiff_dataset_id", S, C.c_char_p, C.c_size_t, c_size_p, H, C.c_size_t)
_proto("stiff_noise_options_init", S, C.POINTER(NoiseOptions), C.c_size_t)
_proto("stiff_robot_options_init", S, C.POINTER(RobotOptions), C.c_size_t)
_proto("stiff_identify_options_init", S, C.POINTER(IdentifyOptions), C.c_size_t)
_proto("stiff_noise_read", S, C.POINTER(NoiseOptions), C.c_char_p)
_proto("stiff_design_random", S, HP, H, C.c_size_t, C.c_uint64)


class DesignRandomOptions(C.Structure):
    _init_ = "stiff_design_random_options_init"
    _fields_ = [
        ("struct_size", C.c_uint32),
        ("count", C.c_uint32),
        ("seed", C.c_uint64),
        ("range_fraction", C.c_double),
        ("load_min_N", C.c_double),
        ("load_max_N", C.c_double),
        ("load_step_N", C.c_double),
        ("min_sigma_m", C.c_double),
        ("q_fixed", c_double_p),
        ("q_fixed_count", C.c_size_t),
        ("use_workspace_box", C.c_uint32),
        ("box_min_m", C.c_double * 3),
        ("box_max_m", C.c_double * 3),
    ]


_proto("stiff_design_random_options_init", S, C.POINTER(DesignRandomOptions), C.c_size_t)
_proto("stiff_design_random_with_options", S, HP, H, C.POINTER(DesignRandomOptions))
_proto("stiff_simulate", S, HP, H, H, C.c_char_p, c_double_p, C.c_size_t, C.POINTER(NoiseOptions))
_proto("stiff_identify", S, HP, H, H, C.POINTER(IdentifyOptions))
_proto("stiff_result_destroy", None, H)
_proto("stiff_result_read_json", S, HP, C.c_char_p)
_proto("stiff_result_write_json", S, H, C.c_char_p)
_proto("stiff_result_json", S, C.c_char_p, C.c_size_t, c_size_p, H)
_proto("stiff_result_joint_stiffness", S, c_double_p, C.c_size_t, c_size_p, H)
_proto("stiff_result_joint_stiffness_se", S, c_double_p, C.c_size_t, c_size_p, H)
_proto("stiff_result_parameters", S, c_double_p, c_double_p, C.c_size_t, c_size_p, H)
_proto("stiff_result_covariance", S, c_double_p, C.c_size_t, c_size_p, H)
_proto("stiff_result_residuals", S, c_double_p, C.c_size_t, c_size_p, H)
_proto("stiff_result_statistics", S, C.POINTER(FitStatistics), H)
_proto("stiff_result_warning", S, C.c_char_p, C.c_size_t, c_size_p, H, C.c_size_t)
_proto("stiff_model_create", S, HP, H, H)
_proto("stiff_model_destroy", None, H)
_proto("stiff_predict", S, c_double_p, H, c_double_p, C.c_size_t, c_double_p)
_proto("stiff_predict_dataset", S, c_double_p, C.c_size_t, c_size_p, H, H)
_proto("stiff_predict_dataset_orientation", S, c_double_p, C.c_size_t, c_size_p, H, H)
_proto("stiff_predict_dataset_cross_fitted", S, c_double_p, C.c_size_t, c_size_p, H, H)
_proto("stiff_result_orientation_residuals", S, c_double_p, C.c_size_t, c_size_p, H)
_proto("stiff_predict_batch", S, c_double_p, C.c_size_t, c_size_p, H, c_double_p, c_double_p,
       C.c_size_t, C.c_size_t)
_proto("stiff_effect_count", C.c_size_t)
_proto("stiff_effect_name", S, C.c_char_p, C.c_size_t, c_size_p, C.c_size_t)
_proto("stiff_effect_describe", S, C.c_char_p, C.c_size_t, c_size_p, H, C.c_char_p)


def last_error() -> str:
    return lib.stiff_last_error().decode("utf-8", "replace")


def check(status: int) -> None:
    """Raise the exception matching a failed status, with the library's message."""
    if status != 0:
        raise error_for(status, last_error())


def ptr(a: np.ndarray):
    return a.ctypes.data_as(c_double_p)


def as_array(values, shape=None) -> np.ndarray:
    a = np.ascontiguousarray(values, dtype=np.float64)
    if shape is not None:
        a = a.reshape(shape)
    return a


def get_doubles(fn, *args) -> np.ndarray:
    """Call a (values, capacity, needed, ...) function: ask for the size, then fetch."""
    needed = C.c_size_t(0)
    st = fn(None, 0, C.byref(needed), *args)
    if st not in (0, BufferTooSmallError.status):
        check(st)
    out = np.empty(needed.value, dtype=np.float64)
    check(fn(ptr(out), needed.value, C.byref(needed), *args))
    return out


def get_string(fn, *args) -> str:
    needed = C.c_size_t(0)
    st = fn(None, 0, C.byref(needed), *args)
    if st not in (0, BufferTooSmallError.status):
        check(st)
    buf = C.create_string_buffer(needed.value)
    check(fn(buf, needed.value, C.byref(needed), *args))
    return buf.value.decode("utf-8")


def require_count(name: str, value, upper: int = 2**32 - 1) -> int:
    """A count (measurements, iterations, pool sizes, trials): a whole number in 1..upper. The C
    options read 0 as "default" and a negative number would wrap to 4 billion."""
    try:
        v = int(value)
        ok = v == value and 1 <= v <= upper
    except (TypeError, ValueError, OverflowError):
        ok = False
    if not ok:
        from .errors import InvalidArgumentError

        too_big = isinstance(value, (int, float)) and value == value and value > upper
        raise InvalidArgumentError(
            f"{name} must be at most {upper} (got {value})" if too_big else
            f"{name} must be an integer >= 1 (got {value})", -1)
    return v


def encode(s):
    """A string for the C ABI. C strings end at the first NUL byte, so one inside the text
    would silently cut it ('joint\\0+link' would mean 'joint'): refused."""
    if s is None:
        return None
    b = os.fsencode(s) if isinstance(s, os.PathLike) else str(s).encode("utf-8")
    if b"\0" in b:
        from .errors import InvalidArgumentError

        raise InvalidArgumentError(f"{os.fsdecode(b)!r} contains a NUL byte", -1)
    return b

# ---------------------------------------------------------------- planning (stiff_plan.h)
PLAN_PROGRESS_FN = C.CFUNCTYPE(C.c_int, C.c_char_p, C.c_uint64, C.c_uint64, C.c_double, C.c_void_p)


class PlanOptions(C.Structure):
    _init_ = "stiff_plan_options_init"
    _fields_ = [
        ("struct_size", C.c_uint32),
        ("count", C.c_uint32),
        ("criterion", C.c_char_p),
        ("seed", C.c_uint64),
        ("pool_poses", C.c_uint32),
        ("pool_loads", C.c_uint32),
        ("range_fraction", C.c_double),
        ("load_min_N", C.c_double),
        ("load_max_N", C.c_double),
        ("load_step_N", C.c_double),
        ("load_max_magnitude_N", C.c_double),
        ("min_sigma_m", C.c_double),
        ("q_fixed", c_double_p),
        ("q_fixed_count", C.c_size_t),
        ("optimizers", C.c_uint32),
        ("annealing_iterations", C.c_uint32),
        ("candidate_file", C.c_char_p),
        ("task", C.c_void_p),
        ("tracker_sigma_m", C.c_double),
        ("tracker_ppm", C.c_double),
        ("progress", PLAN_PROGRESS_FN),
        ("progress_user_data", C.c_void_p),
        ("use_workspace_box", C.c_uint32),
        ("box_min_m", C.c_double * 3),
        ("box_max_m", C.c_double * 3),
        ("fixture_directions", c_double_p),
        ("fixture_direction_count", C.c_size_t),
        ("fixture_forces_N", c_double_p),
        ("fixture_force_count", C.c_size_t),
        ("annealing_initial_temperature", C.c_double),
        ("annealing_initial_swap_count", C.c_uint32),
    ]


_proto("stiff_plan_options_init", S, C.POINTER(PlanOptions), C.c_size_t)
_proto("stiff_plan_create", S, HP, H, C.POINTER(PlanOptions))
_proto("stiff_plan_destroy", None, H)
_proto("stiff_plan_dataset", S, HP, H)
_proto("stiff_plan_json", S, C.c_char_p, C.c_size_t, c_size_p, H)
_proto("stiff_criteria_json", S, C.c_char_p, C.c_size_t, c_size_p, H, H, C.c_double)
_proto("stiff_criteria_task_json", S, C.c_char_p, C.c_size_t, c_size_p, H, H, H, C.c_double)
_proto("stiff_criterion_count", C.c_size_t)
_proto("stiff_criterion_name", S, C.c_char_p, C.c_size_t, c_size_p, C.c_size_t)

# ---------------------------------------------------------------- FMU export (stiff_fmu.h)


class FmuOptions(C.Structure):
    _init_ = "stiff_fmu_options_init"
    _fields_ = [
        ("struct_size", C.c_uint32),
        ("fmi_version", C.c_uint32),
        ("model_identifier", C.c_char_p),
        ("binaries_dir", C.c_char_p),
        ("array_inputs", C.c_uint32),
    ]


_proto("stiff_fmu_options_init", S, C.POINTER(FmuOptions), C.c_size_t)
_proto("stiff_fmu_export", S, C.c_char_p, H, H, C.POINTER(FmuOptions))


# ---- diagnosis (stiff_diagnose.h)
class DiagnoseOptions(C.Structure):
    _init_ = "stiff_diagnose_options_init"
    _fields_ = [
        ("struct_size", C.c_uint32),
        ("model", C.c_char_p),
        ("candidates", C.c_char_p),
        ("alpha", C.c_double),
        ("auto_steps", C.c_uint32),
        ("command_prefix", C.c_char_p),
        ("auto_loop", C.c_uint32),
        ("repeatability_m", C.c_double),
    ]


_proto("stiff_diagnose_options_init", S, C.POINTER(DiagnoseOptions), C.c_size_t)
_proto("stiff_diagnose", S, HP, H, H, H, C.POINTER(DiagnoseOptions))
_proto("stiff_diagnosis_json", S, C.c_char_p, C.c_size_t, c_size_p, H)
_proto("stiff_diagnosis_verdict", S, C.c_char_p, C.c_size_t, c_size_p, H)
_proto("stiff_diagnosis_destroy", None, H)


# ---------------------------------------------------------------- compensation (stiff_compensate.h)
class PathOptions(C.Structure):
    _init_ = "stiff_path_options_init"
    _fields_ = [
        ("struct_size", C.c_uint32),
        ("frame", C.c_double * 6),
        ("tool_rpy", C.c_double * 3),
        ("flags", C.c_uint32),
        ("segment_m", C.c_double),
    ]


PATH_TOOL_RPY = 1
c_int_p = C.POINTER(C.c_int)
_proto("stiff_path_options_init", S, C.POINTER(PathOptions), C.c_size_t)
_proto("stiff_ik_analytic", S, c_int_p, H)
_proto("stiff_tool_pose_batch", S, c_double_p, C.c_size_t, c_size_p, H, c_double_p, C.c_size_t)
_proto("stiff_tool_poses", S, c_double_p, C.c_size_t, c_size_p, H, c_double_p, C.c_size_t, C.c_size_t)
_proto("stiff_ik", S, c_double_p, C.c_size_t, c_size_p, H, c_double_p, c_double_p)
_proto("stiff_ik_path", S, c_double_p, C.c_size_t, c_size_p, c_int_p, H, c_double_p, C.c_size_t,
       c_double_p)
_proto("stiff_compensate_pose", S, c_double_p, H, c_double_p, C.c_size_t, c_double_p)
_proto("stiff_robot_tool_points", S, c_double_p, c_double_p, H)
_proto("stiff_filter_target", S, c_double_p, c_double_p, C.c_size_t, c_size_p, c_int_p, c_double_p,
       H, c_double_p, c_double_p, c_double_p, c_double_p, c_double_p)
_proto("stiff_compensate_path", S, c_double_p, C.c_size_t, c_size_p, c_int_p, H, c_double_p,
       c_double_p, C.c_size_t, c_double_p)
_proto("stiff_truth_deviation", S, c_double_p, C.c_size_t, c_size_p, H, C.c_char_p, c_double_p,
       c_double_p, c_double_p, C.c_size_t)
_proto("stiff_path_read", S, c_double_p, c_double_p, C.POINTER(C.c_uint32), C.c_size_t, c_size_p,
       c_int_p, C.c_char_p, C.POINTER(PathOptions))
_proto("stiff_path_read_flags", S, C.POINTER(C.c_uint32), C.c_size_t, c_size_p, C.c_char_p,
       C.POINTER(PathOptions))
PATH_POINT_RAPID = 1


def defaults(struct):
    """An options struct filled by its stiff_*_options_init: the library's defaults, written in
    one place (the core's option structs). Callers set only what the user gave and leave every
    other field alone."""
    o = struct()
    check(getattr(lib, struct._init_)(C.byref(o), C.sizeof(o)))
    return o


def put_sampling(o, who: str, continuous_step: float, *, range_fraction=None, load_range_N=None,
                 load_step_N=None, min_sigma_m=None, q_fixed=None, workspace_box_m=None) -> list:
    """The random poses and loads of the one sampler, in an options struct that has its fields
    (stiff_plan_options, stiff_design_random_options): only what the caller gave is set, the
    library checks every value. `continuous_step` is how the struct spells "no load grid"
    (0 or negative by release). Returns the arrays the struct points to: keep them alive for
    the call."""
    keep = []
    if range_fraction is not None:
        if not range_fraction > 0:  # 0 would read as "default" in C; the library checks the rest
            from .errors import InvalidArgumentError

            raise InvalidArgumentError(
                f"{who}: range_fraction must be in (0, 1] (got {range_fraction})", -1)
        o.range_fraction = range_fraction
    if load_range_N is not None:
        o.load_min_N, o.load_max_N = float(load_range_N[0]), float(load_range_N[1])
    if load_step_N is not None:
        o.load_step_N = float(load_step_N) if load_step_N > 0 else continuous_step
    if min_sigma_m is not None:
        o.min_sigma_m = float(min_sigma_m)
    if q_fixed is not None:
        # The library checks the count and every value against the joint limits.
        qf = as_array(q_fixed).ravel()
        keep.append(qf)
        o.q_fixed, o.q_fixed_count = ptr(qf), qf.size
    if workspace_box_m is not None:
        lo, hi = (list(map(float, v)) for v in workspace_box_m)
        o.use_workspace_box = 1
        o.box_min_m[:], o.box_max_m[:] = lo, hi
    return keep


def text(value) -> "str | None":
    """A C string field of an options struct as text (None for NULL)."""
    return None if value is None else value.decode("utf-8")
