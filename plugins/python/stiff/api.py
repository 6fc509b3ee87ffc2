"""numpy-first API over the C ABI. SI units everywhere (m, rad, N, N*m); frames: base frame
unless stated otherwise."""
from __future__ import annotations

import ctypes as C
import json
import math
import os
import weakref
from dataclasses import dataclass
from typing import Optional, Sequence

import numpy as np

from . import _capi as _c
from . import _outputs
from ._capi import check, lib
from .errors import InvalidArgumentError

__all__ = ["Robot", "Dataset", "Fit", "Model", "identify", "simulate", "random_design",
           "predict", "effects", "describe_effect", "library_version", "identify_defaults",
           "noise_defaults", "random_design_defaults"]



def library_version() -> str:
    """Version of the loaded libstiff_c."""
    return lib.stiff_version_string().decode()


def _pandas(what: str, instead: str):
    try:
        import pandas
    except ImportError:
        raise ImportError(f"{what} needs pandas, which stiff does not require: install it "
                          f"(pip install pandas) or use {instead}") from None
    return pandas


class _Handle:
    _destroy = None

    def _own(self, handle: C.c_void_p):
        self._h = handle
        self._finalizer = weakref.finalize(self, type(self)._destroy, handle)

    @property
    def _as_parameter_(self):
        return self._h


class Robot(_Handle):
    """A robot description (YAML or URDF): kinematics, limits, measured point, masses.

    `path` is a file or the name of a built-in robot (`stiff.data.names("robots")`). For a URDF,
    `base` and `tip` name the first and last link of the chain (defaults: `base_link`, else the
    root; `tool0` or `flange`, else the only chain end). `measured_point`, `load_point` and
    `tool_com` [m, tip frame] and `tool_mass` [kg] replace the file's values (a URDF has none:
    points at the tip frame's origin, no tool); the load point follows the measured point
    unless given."""

    _destroy = lib.stiff_robot_destroy

    def __init__(self, path: "str | os.PathLike[str]", *, base: Optional[str] = None,
                 tip: Optional[str] = None, measured_point=None, load_point=None,
                 tool_mass: Optional[float] = None, tool_com=None):
        from .data import find

        path = find("robots", path)
        o = _c.defaults(_c.RobotOptions)
        if base:
            o.base_link = _c.encode(base)
        if tip:
            o.tip_link = _c.encode(tip)
        for bit, field, value in ((1, "measured_point_m", measured_point),
                                  (2, "load_point_m", load_point), (8, "tool_com_m", tool_com)):
            if value is not None:
                v = np.asarray(value, dtype=float)
                if v.shape != (3,):
                    raise ValueError(f"{field[:-2]} must be 3 numbers [m], got shape {v.shape}")
                getattr(o, field)[:] = [float(x) for x in v]
                o.set |= bit
        if tool_mass is not None:
            o.tool_mass_kg = float(tool_mass)
            o.set |= 4
        h = C.c_void_p()
        _outputs.note_input(path)
        check(lib.stiff_robot_load_with(C.byref(h), _c.encode(os.fspath(path)), C.byref(o)))
        self._own(h)
        self.path = os.fspath(path)

    @property
    def joint_names(self) -> list[str]:
        return [_c.get_string(lib.stiff_robot_joint_name, self, i) for i in range(self.dof)]

    def _points(self):
        mp, lp, com, mass = np.empty(3), np.empty(3), np.empty(3), C.c_double()
        check(lib.stiff_robot_points(_c.ptr(mp), _c.ptr(lp), C.byref(mass), _c.ptr(com), self))
        return mp, lp, mass.value, com

    @property
    def measured_point(self) -> np.ndarray:
        """Measured point (SMR) in the tip (flange) frame [m]."""
        return self._points()[0]

    @property
    def load_point(self) -> np.ndarray:
        """Point where the force acts, tip (flange) frame [m]."""
        return self._points()[1]

    @property
    def tool_mass(self) -> float:
        """Tool mass [kg]."""
        return self._points()[2]

    @property
    def tool_com(self) -> np.ndarray:
        """Tool centre of mass, tip (flange) frame [m]."""
        return self._points()[3]

    @property
    def notes(self) -> list[str]:
        """What the reader decided: the URDF chain and its tip, locked joints, continuous
        ranges, chain ends left out (empty for a YAML robot without options)."""
        return [l for l in _c.get_string(lib.stiff_robot_notes, self).split("\n") if l]

    def to_yaml(self) -> str:
        """The robot as stiff uses it, in the YAML format (SI units), loadable again."""
        return _c.get_string(lib.stiff_robot_to_yaml, self)

    def to_urdf(self, world=None) -> str:
        """The robot as a URDF serial chain with the same kinematics (links base_link,
        link_1..link_n, tool0 = the flange, tcp = the measured point; masses as point masses),
        for ROS and OLP tools. `world`: the 4 x 4 pose of the base in a `world` link joined by
        a fixed joint, e.g. `fit.registration()` to place a calibrated robot in the
        instrument's frame."""
        if world is None:
            return _c.get_string(lib.stiff_robot_to_urdf, self, None)
        w = np.ascontiguousarray(world, dtype=np.float64)
        if w.shape != (4, 4):
            raise ValueError(f"world must be a 4 x 4 pose, got shape {w.shape}")
        return _c.get_string(lib.stiff_robot_to_urdf, self, _c.ptr(w))

    def save(self, path, world=None) -> None:
        """Write the robot, atomically, in the format its name ends in: .urdf or .xml (URDF,
        `world` as in `to_urdf`), .yaml or .yml (the YAML robot format)."""
        ext = os.path.splitext(os.fspath(path))[1].lower()
        if ext in (".urdf", ".xml"):
            text = self.to_urdf(world)
        elif ext in (".yaml", ".yml"):
            if world is not None:
                raise ValueError("a world pose is written to URDF only; the YAML robot format "
                                 "has no world frame")
            text = self.to_yaml()
        else:
            raise ValueError(f"{os.fspath(path)}: name a robot file .urdf, .xml, .yaml or .yml "
                             f"(got '{ext or 'no extension'}')")
        _outputs.write_text(path, text)

    def calibrated(self, fit: "Fit") -> "Robot":
        """This robot with the fit's pose-independent geometry (joint offsets, kinematic
        errors, tool) built into its chain; `notes` names what a robot description cannot
        hold (registration, compliance, harmonics). `to_yaml()` writes it for other tools."""
        if not isinstance(fit, Fit):
            raise TypeError(f"fit must be a Fit, not {type(fit).__name__}")
        h = C.c_void_p()
        check(lib.stiff_robot_calibrated(C.byref(h), self, fit))
        r = Robot.__new__(Robot)
        r._own(h)
        r.path = self.path
        return r

    @property
    def dof(self) -> int:
        n = C.c_size_t()
        check(lib.stiff_robot_dof(C.byref(n), self))
        return n.value

    @property
    def name(self) -> str:
        return _c.get_string(lib.stiff_robot_name, self)

    @property
    def limits(self) -> tuple[np.ndarray, np.ndarray]:
        """(lower, upper) joint limits [rad]."""
        n = self.dof
        lo, hi = np.empty(n), np.empty(n)
        needed = C.c_size_t()
        check(lib.stiff_robot_limits(_c.ptr(lo), _c.ptr(hi), n, C.byref(needed), self))
        return lo, hi

    def tool_pose(self, q) -> np.ndarray:
        """Pose of the measured point at joint positions q [rad], base frame [m]: 4 x 4 for
        one pose (n values), (N, 4, 4) for N poses (N x n), in one call."""
        qa = np.asarray(q, dtype=np.float64)
        if qa.ndim == 1:
            qa = _c.as_array(q)
            out = np.empty(16)
            check(lib.stiff_robot_tool_pose(_c.ptr(out), self, _c.ptr(qa), qa.size))
            return out.reshape(4, 4)
        if qa.ndim != 2:
            raise ValueError(f"q must be n or N x n joint values, got shape {qa.shape}")
        qa = np.ascontiguousarray(qa)
        out = np.empty((qa.shape[0], 4, 4))
        needed = C.c_size_t()
        check(lib.stiff_tool_poses(_c.ptr(out), out.size, C.byref(needed), self, _c.ptr(qa),
                                   qa.shape[0], qa.shape[1]))
        return out

    def jacobian(self, q) -> np.ndarray:
        """Geometric Jacobian at the measured point, base frame: 6 x n for one pose (n
        values), (N, 6, n) for N poses (N x n)."""
        qa = np.asarray(q, dtype=np.float64)
        if qa.ndim == 2:
            qa = np.ascontiguousarray(qa)
            out = np.empty((qa.shape[0], 6, self.dof))
            needed = C.c_size_t()
            check(lib.stiff_robot_jacobians(_c.ptr(out), out.size, C.byref(needed), self,
                                            _c.ptr(qa), qa.shape[0], qa.shape[1]))
            return out
        if qa.ndim != 1:
            raise ValueError(f"q must be n or N x n joint values, got shape {qa.shape}")
        qa = _c.as_array(q)
        return _c.get_doubles(lib.stiff_robot_jacobian, self, _c.ptr(qa), qa.size).reshape(6, -1)

    def __repr__(self) -> str:
        return f"Robot({self.name!r}, dof={self.dof}, path={self.path!r})"


class Dataset(_Handle):
    """One experiment: poses q [rad], loads [N, N*m], displacements [m] (base frame)."""

    _destroy = lib.stiff_dataset_destroy

    def __init__(self, handle: C.c_void_p):
        self._own(handle)

    @classmethod
    def read(cls, path, robot: Optional[Robot] = None) -> "Dataset":
        """Read a measurement CSV (docs/formats.md); ParseError carries path, line, column."""
        h = C.c_void_p()
        _outputs.note_input(path)
        check(lib.stiff_dataset_read_csv(C.byref(h), robot, _c.encode(os.fspath(path))))
        return cls(h)

    @classmethod
    def from_arrays(cls, q, force, moment=None, displacement=None, sigma_d=None) -> "Dataset":
        """Build from arrays: q (N x n) [rad], force (N x 3) [N], optional moment (N x 3)
        [N*m], displacement (N x 3) [m], sigma_d (N) [m]."""
        qa = np.atleast_2d(_c.as_array(q))
        rows, dof = qa.shape
        fa = _c.as_array(force, (rows, 3))
        opt = [None if v is None else _c.as_array(v, (rows, 3) if k < 2 else (rows,))
               for k, v in enumerate((moment, displacement, sigma_d))]
        h = C.c_void_p()
        check(lib.stiff_dataset_create(C.byref(h), rows, dof, _c.ptr(qa), _c.ptr(fa),
                                       *[None if v is None else _c.ptr(v) for v in opt]))
        return cls(h)

    def write(self, path) -> None:
        """Write in SI units, atomically."""
        check(lib.stiff_dataset_write_csv(self, _c.encode(_outputs.target(path))))

    def __len__(self) -> int:
        rows = C.c_size_t()
        check(lib.stiff_dataset_size(C.byref(rows), None, self))
        return rows.value

    @property
    def dof(self) -> int:
        d = C.c_size_t()
        check(lib.stiff_dataset_size(None, C.byref(d), self))
        return d.value

    def _has(self, column: int) -> bool:
        p = C.c_int()
        check(lib.stiff_dataset_has(C.byref(p), self, column))
        return bool(p.value)

    def _get(self, column: int, width: int) -> Optional[np.ndarray]:
        if not self._has(column):
            return None
        v = _c.get_doubles(lib.stiff_dataset_get, self, column)
        return v.reshape(-1, width) if width > 1 else v

    @property
    def q(self) -> np.ndarray:
        return self._get(0, self.dof)

    @property
    def force(self) -> np.ndarray:
        return self._get(1, 3)

    @property
    def moment(self) -> Optional[np.ndarray]:
        return self._get(2, 3)

    @property
    def displacement(self) -> Optional[np.ndarray]:
        return self._get(3, 3)

    @displacement.setter
    def displacement(self, d) -> None:
        da = _c.as_array(d, (len(self), 3))
        check(lib.stiff_dataset_set_displacement(self, _c.ptr(da), da.shape[0]))

    @property
    def sigma_d(self) -> Optional[np.ndarray]:
        return self._get(5, 1)

    @property
    def absolute(self) -> np.ndarray:
        """N booleans: True for an absolute row (target position in the instrument frame)."""
        return self._get(7, 1).astype(bool)

    @property
    def position(self) -> Optional[np.ndarray]:
        """N x 3 target positions in the instrument frame [m] (NaN on displacement rows), or
        None when the file has no px, py, pz columns."""
        return self._get(8, 3)

    @property
    def orientation(self) -> Optional[np.ndarray]:
        """N x 3 measured probe orientations as rotation vectors [rad], instrument frame (NaN on
        rows without one), or None when the file has no a, b, c columns."""
        return self._get(11, 3)

    @property
    def temperature(self) -> Optional[np.ndarray]:
        """N temperatures [deg C], or None without a temp column."""
        return self._get(10, 1)

    @property
    def observed(self) -> Optional[np.ndarray]:
        """N x 3 what a model predicts for each row: the absolute position of an absolute row,
        the displacement of a displacement row [m] (None when neither is measured)."""
        p, d = self.position, self.displacement
        if p is None:
            return d
        if d is None:
            return p
        return np.where(self.absolute[:, None], p, d)

    @property
    def wrench(self) -> np.ndarray:
        """N x 6 (force, moment) at the load point, base frame."""
        m = self.moment
        return np.hstack([self.force, m if m is not None else np.zeros((len(self), 3))])

    @property
    def ids(self) -> list[str]:
        return [_c.get_string(lib.stiff_dataset_id, self, r) for r in range(len(self))]

    def to_dataframe(self):
        """The rows as a pandas DataFrame (pandas is optional: ImportError says so)."""
        pd = _pandas("Dataset.to_dataframe()", "Dataset.q, .force, .displacement (numpy)")
        cols = {"id": self.ids}
        for j in range(self.dof):
            cols[f"q{j + 1}_rad"] = self.q[:, j]
        for k, a in enumerate("xyz"):
            cols[f"f{a}_N"] = self.force[:, k]
        d = self.displacement
        if d is not None:
            for k, a in enumerate("xyz"):
                cols[f"d{a}_m"] = d[:, k]
        return pd.DataFrame(cols)

    def __repr__(self) -> str:
        return f"Dataset({len(self)} measurements, dof={self.dof}, displacements={'yes' if self._has(3) else 'no'})"


@dataclass
class FitStatistics:
    measurements: int
    rank: int
    dof: int
    rms_m: float
    sigma_hat_m: float
    noise_floor_m: float
    chi2: float
    condition_number: float
    outliers: int
    warnings: int
    oriented_rows: int = 0  # absolute rows whose measured orientation the fit used
    orientation_rms_rad: float = 0.0
    orientation_mean_rad: float = 0.0
    orientation_max_rad: float = 0.0
    orientation_length_m: float = 0.0  # 1 rad of orientation error weighed as this many m
    model_error_m: float = 0.0  # the model's error added to each absolute row's sigma_p
    model_error_rad: float = 0.0  # the same for the orientations (rows with sigma_o)


class Fit(_Handle):
    """An identified model: effects, parameters with standard errors, fit statistics."""

    _destroy = lib.stiff_result_destroy

    def __init__(self, handle: C.c_void_p):
        self._own(handle)
        self._json = None

    @classmethod
    def read(cls, path) -> "Fit":
        h = C.c_void_p()
        _outputs.note_input(path)
        check(lib.stiff_result_read_json(C.byref(h), _c.encode(os.fspath(path))))
        return cls(h)

    def write(self, path) -> None:
        check(lib.stiff_result_write_json(self, _c.encode(_outputs.target(path))))

    def registration(self, session: Optional[str] = None) -> np.ndarray:
        """Pose of the robot's base in the instrument frame of `session` (4 x 4, m): the
        registration the fit identified. None: the fit's only session."""
        pose = np.empty(16)
        check(lib.stiff_result_registration(_c.ptr(pose), self,
                                             _c.encode(session) if session else None))
        return pose.reshape(4, 4)

    @property
    def json(self) -> dict:
        if self._json is None:
            self._json = json.loads(_c.get_string(lib.stiff_result_json, self))
        return self._json

    @property
    def model(self) -> list[str]:
        return list(self.json["model"])

    @property
    def stiffness(self) -> np.ndarray:
        """Joint stiffness [N*m/rad]. A joint the data could not identify is held at compliance
        c = 0, infinitely stiff: its value is inf (see `identified` and `joint_status`)."""
        k = _c.get_doubles(lib.stiff_result_joint_stiffness, self)
        # The C ABI reports NaN for a joint it did not identify; the model holds it at c = 0.
        k[np.isnan(k) & ~self.identified] = np.inf
        return k

    @property
    def joint_status(self) -> list[str]:
        """Per joint: 'identified' or 'not identified, held infinitely stiff (c = 0)'."""
        k = _c.get_doubles(lib.stiff_result_joint_stiffness, self)
        return ["identified" if ok else
                ("not identified, held infinitely stiff (c = 0)" if math.isnan(v)
                 else f"not identified, held at {v:.6g} N*m/rad")
                for ok, v in zip(self.identified, k)]

    def summary(self) -> str:
        """A plain-text table: joint stiffness with standard error, or why it is not given."""
        k, se = self.stiffness, self.stiffness_se
        rows = []
        for j, (kj, sj, st) in enumerate(zip(k, se, self.joint_status)):
            if st == "identified":
                rows.append(f"joint {j + 1}: k = {kj:.6g} N*m/rad +- {sj:.3g}")
            else:
                rows.append(f"joint {j + 1}: {st}")
        return "\n".join([repr(self)] + rows)

    @property
    def stiffness_se(self) -> np.ndarray:
        return _c.get_doubles(lib.stiff_result_joint_stiffness_se, self)

    @property
    def identified(self) -> np.ndarray:
        return np.array([j["identified"] for j in self.json["joints"]], dtype=bool)

    @property
    def parameters(self) -> np.ndarray:
        """Every model parameter (SI), in model order."""
        return self._parameters_and_errors()[0]

    @property
    def standard_errors(self) -> np.ndarray:
        """Standard errors of the parameters (NaN where not identified)."""
        return self._parameters_and_errors()[1]

    def _parameters_and_errors(self) -> tuple[np.ndarray, np.ndarray]:
        needed = C.c_size_t()
        lib.stiff_result_parameters(None, None, 0, C.byref(needed), self)
        v, se = np.empty(needed.value), np.empty(needed.value)
        check(lib.stiff_result_parameters(_c.ptr(v), _c.ptr(se), needed.value, C.byref(needed), self))
        return v, se

    @property
    def parameter_table(self) -> list[dict]:
        return list(self.json["parameters"])

    @property
    def covariance(self) -> np.ndarray:
        c = _c.get_doubles(lib.stiff_result_covariance, self)
        p = int(round(np.sqrt(c.size)))
        return c.reshape(p, p)

    @property
    def residuals(self) -> np.ndarray:
        return _c.get_doubles(lib.stiff_result_residuals, self).reshape(-1, 3)

    @property
    def orientation_residuals(self) -> Optional[np.ndarray]:
        """N x 3 orientation residuals Log(R_measured R_predicted^T) [rad] (NaN on rows without
        a measured orientation), or None when the fit used no orientation."""
        if not self.statistics.oriented_rows:
            return None
        return _c.get_doubles(lib.stiff_result_orientation_residuals, self).reshape(-1, 3)

    @property
    def statistics(self) -> FitStatistics:
        s = _c.FitStatistics()
        s.struct_size = C.sizeof(s)
        check(lib.stiff_result_statistics(C.byref(s), self))
        return FitStatistics(*(getattr(s, f) for f, _ in _c.FitStatistics._fields_[1:]))

    @property
    def warnings(self) -> list[str]:
        return [_c.get_string(lib.stiff_result_warning, self, i) for i in range(self.statistics.warnings)]

    @property
    def outliers(self) -> list[dict]:
        return list(self.json.get("outliers", []))

    def to_dataframe(self):
        """The parameter table as a pandas DataFrame (pandas is optional: ImportError says so)."""
        pd = _pandas("Fit.to_dataframe()", "Fit.parameter_table (a list of dicts)")
        return pd.DataFrame(self.parameter_table)

    def __repr__(self) -> str:
        s = self.statistics
        return (f"Fit(model={'+'.join(self.model)!r}, {s.measurements} measurements, "
                f"rms={s.rms_m * 1e6:.2f} um, noise floor={s.noise_floor_m * 1e6:.2f} um)")


class Model(_Handle):
    """A robot with an identified fit, ready to predict deflections."""

    _destroy = lib.stiff_model_destroy

    def __init__(self, robot: Robot, fit: Fit):
        h = C.c_void_p()
        check(lib.stiff_model_create(C.byref(h), robot, fit))
        self._own(h)
        self.robot, self.fit = robot, fit

    def predict(self, q, wrench) -> np.ndarray:
        """Deflection (dx, dy, dz [m], rx, ry, rz [rad]) of the measured point, base frame,
        for poses q (n or N x n, rad) and wrenches (6 or N x 6: force [N] and moment [N*m]
        at the load point, base frame; a 3-vector is a pure force)."""
        qa = np.atleast_2d(_c.as_array(q))
        w = np.atleast_2d(_c.as_array(wrench))
        if qa.ndim != 2 or w.ndim != 2:
            raise ValueError(f"q must be n or N x n and wrench 3, 6, N x 3 or N x 6; got shapes "
                             f"{np.shape(q)} and {np.shape(wrench)}")
        dof = self.robot.dof
        if qa.shape[1] != dof:
            raise ValueError(f"q has {qa.shape[1]} columns, the robot has {dof} joints")
        if w.shape[1] not in (3, 6):
            raise ValueError(f"wrench has {w.shape[1]} columns; give 3 (force [N]) or 6 (force "
                             "[N], moment [N*m])")
        if w.shape[0] != qa.shape[0] and w.shape[0] != 1:
            raise ValueError(f"q has {qa.shape[0]} rows and wrench {w.shape[0]}: give one "
                             "wrench per pose, or one for all")
        if w.shape[1] == 3:
            w = np.hstack([w, np.zeros((w.shape[0], 3))])
        if w.shape[0] == 1 and qa.shape[0] > 1:
            w = np.repeat(w, qa.shape[0], axis=0)
        w = np.ascontiguousarray(w)
        rows, n = qa.shape
        out = np.empty((rows, 6))
        needed = C.c_size_t()
        check(lib.stiff_predict_batch(_c.ptr(out), out.size, C.byref(needed), self, _c.ptr(qa),
                                      _c.ptr(w), rows, n))
        return out[0] if np.ndim(q) == 1 else out

    def predict_dataset(self, data: "Dataset", cross_fit_sessions: bool = False) -> np.ndarray:
        """What the model predicts for every row of `data`, N x 3 [m]: the displacement of a
        displacement row, the target position in the instrument frame of an absolute row (the
        registration of its session, which the fit must have identified).

        cross_fit_sessions: `data` is a measured session the fit has not seen; its own
        parameters (drift) are estimated from its readings, cross-fitted (each half of the rows
        predicted with the values from the other half), as the diagnosis scores validation
        data (docs/effects.md, drift)."""
        f = lib.stiff_predict_dataset_cross_fitted if cross_fit_sessions else lib.stiff_predict_dataset
        return _c.get_doubles(f, self, data).reshape(-1, 3)

    def predict_orientation(self, data: "Dataset") -> np.ndarray:
        """The probe orientation the model predicts for every absolute row of `data`, N x 3
        rotation vectors [rad] in the instrument frame (the flange's, turned by
        tool_orientation, the deflection and the registration); NaN on displacement rows."""
        return _c.get_doubles(lib.stiff_predict_dataset_orientation, self, data).reshape(-1, 3)


METHODS = {"auto": 0, "linear": 1, "ceres": 2}  # stiff_method


def identify_defaults() -> dict:
    """The library's identification defaults (stiff_identify_options_init): what every
    argument of identify() left at None and every unset option of `stiff identify` takes."""
    o = _c.defaults(_c.IdentifyOptions)
    return {"model": _c.text(o.model), "loss": _c.text(o.loss), "loss_scale_m": o.loss_scale_m,
            "method": next(k for k, v in METHODS.items() if v == o.method),
            "max_iterations": o.max_iterations, "max_relative_se": o.max_relative_se,
            "orientation_length_m": o.orientation_length_m or None,
            "select_terms": o.select_terms > 0}


def identify(robot: Robot, data: Dataset, model: Optional[str] = None,
             loss: Optional[str] = None, loss_scale_m: Optional[float] = None,
             method: Optional[str] = None, max_iterations: Optional[int] = None,
             max_relative_se: Optional[float] = None, start: Optional["Fit"] = None,
             refit: Optional[str] = None,
             orientation_length_m: Optional[float] = None,
             use_orientation: bool = True,
             select_terms: Optional[bool] = None) -> Fit:
    """Identify the model (effects joined by '+') from measured displacements and/or absolute
    positions (e.g. model='registration+tool+joint_offset+kinematic' on absolute data).
    An argument left at None takes the library's default (identify_defaults()); the library
    checks every value and its message names the option. `method`: auto, linear or ceres.
    `max_relative_se`: a parameter whose standard error exceeds this many times its typical
    magnitude and also a third of its value (t < 3) is held (docs/identifiability.md); 0 keeps
    only the structural rank test. `start`: a previous fit of the robot whose parameters start
    this one; with `refit` (effects joined by '+', e.g. 'registration'), only those effects are
    fitted and every other parameter is kept from `start` (a new placement of the instrument
    registered to a calibrated robot). Absolute rows with a measured orientation add the
    orientation residual when the model has the probe's frame (tool_orientation);
    `orientation_length_m` > 0 weighs it as the position error it makes this far from the probe
    (None: estimated from the residuals); `use_orientation=False` fits the positions alone.
    `select_terms`: True keeps an optional term of an effect (nonlinear_joint's second-order
    terms, gravity_compensator's second harmonics) only when it lowers the Bayesian information
    criterion (docs/identifiability.md); False fits them all."""
    o = _c.defaults(_c.IdentifyOptions)
    for name, v in (("model", model), ("loss", loss), ("refit", refit)):
        if v is not None and not isinstance(v, str):  # ctypes would take bytes or a pointer
            raise TypeError(f"{name} must be a string such as "
                            f"{'registration' if name == 'refit' else 'joint+link'!r}, not "
                            f"{type(v).__name__}")
    if model is not None:
        o.model = _c.encode(model)
    if loss is not None:
        o.loss = _c.encode(loss)
    if loss_scale_m is not None:
        o.loss_scale_m = loss_scale_m
    if max_iterations is not None:
        # a uint32 field: a negative count would wrap around instead of being refused
        o.max_iterations = _c.require_count("max_iterations", max_iterations)
    if method is not None:
        if method not in METHODS:
            raise InvalidArgumentError(
                f"identify: unknown method {method!r} (use {', '.join(METHODS)})", -1)
        o.method = METHODS[method]
    if max_relative_se is not None:
        # Python follows the core: 0 turns the test off. The C field reads 0 as "default" and
        # a negative value as "off", so a negative value cannot reach the core's check.
        if not (math.isfinite(max_relative_se) and max_relative_se >= 0):
            raise InvalidArgumentError(
                f"identify: max_relative_se must be a finite value >= 0 (got {max_relative_se})", -1)
        o.max_relative_se = max_relative_se if max_relative_se > 0 else -1.0
    if select_terms is not None:
        if not isinstance(select_terms, bool):
            raise TypeError(f"select_terms must be True or False, not {type(select_terms).__name__}")
        o.select_terms = 1 if select_terms else -1
    if start is not None:
        if not isinstance(start, Fit):
            raise TypeError(f"start must be a Fit, not {type(start).__name__}")
        o.start = start._as_parameter_
    if refit:
        o.refit = _c.encode(refit)
    if orientation_length_m is not None:
        # The C field reads 0 as "estimated" and a negative value as "positions only".
        if not (math.isfinite(orientation_length_m) and orientation_length_m > 0):
            raise InvalidArgumentError("identify: orientation_length_m must be a finite length "
                                       f"> 0 [m] (got {orientation_length_m})", -1)
        o.orientation_length_m = orientation_length_m
    if not use_orientation:
        o.orientation_length_m = -1.0
    h = C.c_void_p()
    check(lib.stiff_identify(C.byref(h), robot, data, C.byref(o)))
    return Fit(h)


def random_design_defaults() -> dict:
    """The library's random-design defaults (stiff_design_random_options_init): count, seed,
    range_fraction, load_range_N, load_step_N, min_sigma_m."""
    o = _c.defaults(_c.DesignRandomOptions)
    return {"count": o.count, "seed": o.seed, "range_fraction": o.range_fraction,
            "load_range_N": (o.load_min_N, o.load_max_N), "load_step_N": o.load_step_N,
            "min_sigma_m": o.min_sigma_m}


def random_design(robot: Robot, count: Optional[int] = None, seed: Optional[int] = None, *,
                  range_fraction: Optional[float] = None, load_range_N=None,
                  load_step_N: Optional[float] = None, min_sigma_m: Optional[float] = None,
                  q_fixed=None, workspace_box_m=None) -> Dataset:
    """Random poses and loads: by default uniform in 95% of the joint ranges with loads of
    15-35 N per axis and random signs. The keywords are those of `plan` (the same sampler as
    the planner's candidate pool): `q_fixed` holds joints at values [rad] (NaN = free),
    `load_step_N` puts the per-axis magnitudes on a grid (0 or None: continuous),
    `workspace_box_m` = (min, max) keeps poses whose measured point lies in the box. An
    argument left at None takes the library's default; the library checks every value."""
    o = _c.defaults(_c.DesignRandomOptions)
    if count is not None:
        o.count = _c.require_count("count", count, 1000000)
    if seed is not None:
        o.seed = seed
    keep = _c.put_sampling(o, "random design", 0.0, range_fraction=range_fraction,
                           load_range_N=load_range_N, load_step_N=load_step_N,
                           min_sigma_m=min_sigma_m, q_fixed=q_fixed,
                           workspace_box_m=workspace_box_m)
    h = C.c_void_p()
    check(lib.stiff_design_random_with_options(C.byref(h), robot, C.byref(o)))
    del keep
    return Dataset(h)


NOISE_FIELDS = ("tracker_sigma_m", "tracker_ppm", "force_relative", "force_absolute_N",
                "joint_sigma_rad", "outlier_rate", "outlier_size_m", "seed")


def noise_defaults() -> dict:
    """The virtual robot's default noise (stiff_noise_options_init): what every noise argument
    of simulate() left at None and every unset option of `stiff simulate` takes."""
    o = _c.defaults(_c.NoiseOptions)
    d = {k: getattr(o, k) for k in NOISE_FIELDS}
    d["tracker_position_m"] = list(o.tracker_position_m)
    return d


def simulate(robot: Robot, design: Optional[Dataset] = None, *, stiffness=None, truth=None,
             tracker_sigma_m: Optional[float] = None, tracker_ppm: Optional[float] = None,
             force_relative: Optional[float] = None, force_absolute_N: Optional[float] = None,
             joint_sigma_rad: Optional[float] = None, outlier_rate: Optional[float] = None,
             outlier_size_m: Optional[float] = None, seed: Optional[int] = None,
             tracker_position_m=None) -> Dataset:
    """Simulate measurements of `design` on the virtual robot. The truth is a YAML file or the
    name of a built-in one (`truth`, e.g. "rokae_backlash"), or the joint stiffness
    `stiffness` [N*m/rad]. A noise argument left at None takes the library's default
    (noise_defaults()); 0 means no such error. The library checks every value."""
    o = _c.defaults(_c.NoiseOptions)
    given = dict(tracker_sigma_m=tracker_sigma_m, tracker_ppm=tracker_ppm,
                 force_relative=force_relative, force_absolute_N=force_absolute_N,
                 joint_sigma_rad=joint_sigma_rad, outlier_rate=outlier_rate,
                 outlier_size_m=outlier_size_m)
    for name, value in given.items():
        if value is not None:
            setattr(o, name, float(value))
    if seed is not None:
        o.seed = seed
    if tracker_position_m is not None:
        v = np.asarray(tracker_position_m, dtype=float)
        if v.shape != (3,):
            raise ValueError(f"tracker_position_m must be 3 numbers [m], got shape {v.shape}")
        o.tracker_position_m[:] = [float(x) for x in v]
    k = None if stiffness is None else _c.as_array(stiffness)
    if truth is not None:
        from .data import find

        truth = find("truths", truth)
    if k is not None and k.ndim != 1:
        raise ValueError(f"stiffness must be one value per joint, got shape {k.shape}")
    _outputs.note_input(truth)
    h = C.c_void_p()
    check(lib.stiff_simulate(C.byref(h), robot, design,
                             None if truth is None else _c.encode(os.fspath(truth)),
                             None if k is None else _c.ptr(k), 0 if k is None else k.size,
                             C.byref(o)))
    return Dataset(h)


def read_noise(path) -> dict:
    """Read a noise YAML file (or a built-in one by name) into keyword arguments of simulate()."""
    from .data import find

    path = find("truths", path)
    o = _c.NoiseOptions()
    o.struct_size = C.sizeof(o)
    _outputs.note_input(path)
    check(lib.stiff_noise_read(C.byref(o), _c.encode(os.fspath(path))))
    return dict(tracker_sigma_m=o.tracker_sigma_m, tracker_ppm=o.tracker_ppm,
                tracker_position_m=list(o.tracker_position_m), force_relative=o.force_relative,
                force_absolute_N=o.force_absolute_N, joint_sigma_rad=o.joint_sigma_rad,
                outlier_rate=o.outlier_rate, outlier_size_m=o.outlier_size_m, seed=o.seed)


def predict(robot: Robot, fit: Fit, q, wrench) -> np.ndarray:
    """Predicted deflection for poses and wrenches (see Model.predict)."""
    return Model(robot, fit).predict(q, wrench)


def effects() -> list[str]:
    """Names of every physical effect the library knows."""
    return [_c.get_string(lib.stiff_effect_name, i) for i in range(lib.stiff_effect_count())]


def describe_effect(name: str, robot: Optional[Robot] = None) -> dict:
    """Description, reference and parameters (name, unit, meaning, bounds) of an effect."""
    return json.loads(_c.get_string(lib.stiff_effect_describe, robot, _c.encode(name)))
