"""Import absolute measurements from a tracker program's export into stiff's measurement format.

A tracker export is a table: one row per pose, a separator, maybe decimal commas, its own
column names and units. `import_table` maps its columns onto the quantities of the absolute
measurement format (docs/formats.md): joints `q1..qn`, the target position `px, py, pz` in the
instrument frame, optional probe orientation `a, b, c` (Euler angles, convention named in the
metadata), `temp`, wrench `fx..mz`, standard deviations `sigma_p`, `sigma_o`, and the `id` and
`session` labels. Each output column is `quantity_unit` and takes its values from an
expression over the source columns:

    COLUMN                      the value as written (decimal comma turned into a point)
    (empty)                     drop a quantity the preset maps (e.g. a missing sigma)
    COLUMN + COLUMN - COLUMN    a sum, e.g. target plus measured error
    rms(COLUMN, COLUMN, ...)    quadratic mean, e.g. one sigma from per-axis sigmas

Values are copied as text when they come from one column, so nothing is rounded; computed
sums are written with the shortest text that reads back to the same double, quadratic means
(uncertainties) with six significant digits. Nothing is written unless every row converts.
"""
from __future__ import annotations

import math
import os
import re
import shlex
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional, Sequence

from .errors import StiffError

# Quantities of the absolute measurement format and the units each accepts.
_LENGTH = ("m", "mm", "um")
_ANGLE = ("rad", "deg")
QUANTITIES: dict[str, tuple[str, ...]] = {
    **{f"p{a}": _LENGTH for a in "xyz"},
    **{k: _ANGLE for k in "abc"},
    "temp": ("C",),
    **{f"f{a}": ("N",) for a in "xyz"},
    **{f"m{a}": ("Nm", "Nmm") for a in "xyz"},
    "sigma_p": _LENGTH,
    "sigma_o": ("deg", "rad"),
}
_JOINT = re.compile(r"^q([1-9][0-9]*)$")
_GROUPS = (("px", "py", "pz"), ("a", "b", "c"), ("fx", "fy", "fz"), ("mx", "my", "mz"))
EULER = ("xyz", "zyx")

# The two public datasets stiff ships (examples/real/): their authors' export formats.
PRESETS: dict[str, dict] = {
    "jacobi2025": {
        "description": "UR5 / GTS3800 (Jacobi 2025): measured = target + error, base frame, "
                       "joints in degrees",
        "sep": ",", "decimal": ".",
        "columns": {
            "id": "step_order",
            **{f"q{i}_deg": f"joint_{i}" for i in range(1, 7)},
            "px_mm": "x_t + x_dif", "py_mm": "y_t + y_dif", "pz_mm": "z_t + z_dif",
        },
        "metadata": {"robot": "ur5",
                     "frame": "robot base (tracker registered by the authors)",
                     "source": "Jacobi 2025, UR5, GTS3800 laser tracker"},
    },
    "landgraf2021": {
        "description": "UR10 / Leica tracker + T-Mac (Landgraf et al. 2021): semicolons, decimal "
                       "commas, joints in rad, pose in mm and intrinsic XYZ degrees",
        "sep": ";", "decimal": ",", "euler": "xyz",
        "columns": {
            **{f"q{i}_rad": n for i, n in enumerate(
                ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint",
                 "wrist_2_joint", "wrist_3_joint"], start=1)},
            "px_mm": "measurement_x", "py_mm": "measurement_y", "pz_mm": "measurement_z",
            "a_deg": "measurement_rx", "b_deg": "measurement_ry", "c_deg": "measurement_rz",
            "temp_C": "measurement_temperature",
            "sigma_p_mm": "rms(measurement_std_x, measurement_std_y, measurement_std_z)",
            "sigma_o_deg": "rms(measurement_std_rx, measurement_std_ry, measurement_std_rz)",
        },
        "metadata": {"robot": "ur10", "frame": "laser tracker",
                     "source": "Landgraf et al. 2021, UR10, Leica laser tracker with T-Mac"},
    },
}


class ImportFormatError(StiffError, ValueError):
    """A tracker export or a mapping that cannot be converted; the message names file:line."""

    status = -3


@dataclass
class ImportResult:
    rows: int
    columns: list[str]
    text: str
    skipped: int = 0
    metadata: dict = field(default_factory=dict)


def _fail(msg: str):
    raise ImportFormatError(msg)


def parse_target(target: str) -> tuple[str, str]:
    """`px_mm` -> ('px', 'mm'); `id`/`session` -> (name, ''). Errors name what is accepted."""
    if target in ("id", "session"):
        return target, ""
    for q in sorted(QUANTITIES, key=len, reverse=True):
        if target.startswith(q + "_"):
            unit = target[len(q) + 1:]
            if unit not in QUANTITIES[q]:
                _fail(f"column '{target}': unit '{unit}' is not one of "
                      f"{', '.join(QUANTITIES[q])} for {q}")
            return q, unit
    m = re.match(r"^(q[0-9]+)_(.*)$", target)
    if m and _JOINT.match(m.group(1)):
        if m.group(2) not in _ANGLE:
            _fail(f"column '{target}': joint unit must be rad or deg")
        return m.group(1), m.group(2)
    _fail(f"unknown output column '{target}' (quantities: id, session, q1..qn, "
          f"{', '.join(QUANTITIES)}, each with a unit suffix such as px_mm or q1_deg)")


class _Expr:
    """One output column's expression over source columns."""

    def __init__(self, text: str, header: list[str], where: str):
        self.text = text.strip()
        idx = {h: i for i, h in enumerate(header)}

        def col(name: str) -> int:
            name = name.strip()
            if name not in idx:
                _fail(f"{where}: no column '{name}' (columns: {', '.join(header)})")
            return idx[name]

        if self.text in idx:
            self.kind, self.cols, self.signs = "copy", [idx[self.text]], [1.0]
            return
        m = re.match(r"^rms\((.*)\)$", self.text)
        if m:
            self.kind = "rms"
            self.cols = [col(c) for c in m.group(1).split(",")]
            self.signs = [1.0] * len(self.cols)
            return
        parts = re.split(r"\s*([+-])\s*", self.text)
        if len(parts) < 3 or parts[0] == "":
            col(self.text)  # raises: neither a column nor an expression
        self.kind, self.cols, self.signs = "sum", [col(parts[0])], [1.0]
        for op, name in zip(parts[1::2], parts[2::2]):
            self.cols.append(col(name))
            self.signs.append(1.0 if op == "+" else -1.0)

    def value(self, fields: list[str], number) -> str:
        if self.kind == "copy":
            return number(self.cols[0])
        vals = [float(number(c)) for c in self.cols]
        if self.kind == "rms":
            # An uncertainty: six significant digits are more than it knows.
            return f"{math.sqrt(sum(x * x for x in vals) / len(vals)):.6g}"
        return repr(sum(s * x for s, x in zip(self.signs, vals)))


def _split(line: str, sep: str) -> list[str]:
    """Split one line; fields may be quoted with double quotes (as in CSV)."""
    if '"' not in line:
        return [f.strip() for f in line.split(sep)]
    out, cur, quoted, i = [], [], False, 0
    while i < len(line):
        ch = line[i]
        if quoted:
            if ch == '"' and i + 1 < len(line) and line[i + 1] == '"':
                cur.append('"')
                i += 1
            elif ch == '"':
                quoted = False
            else:
                cur.append(ch)
        elif ch == '"':
            quoted = True
        elif ch == sep:
            out.append("".join(cur).strip())
            cur = []
        else:
            cur.append(ch)
        i += 1
    out.append("".join(cur).strip())
    return out


def import_table(path: "str | os.PathLike[str]", output: "str | os.PathLike[str] | None" = None, *,
                 preset: Optional[str] = None, sep: Optional[str] = None,
                 decimal: Optional[str] = None, columns: Optional[dict[str, str]] = None,
                 euler: Optional[str] = None, session: Optional[str] = None,
                 robot: Optional[str] = None, metadata: Optional[dict[str, str]] = None,
                 every: int = 1, id_prefix: Optional[str] = None,
                 command: Optional[str] = None) -> ImportResult:
    """Convert a tracker export into the absolute measurement format.

    `columns` maps output columns (`px_mm`, `q1_deg`, `id`, `session`, ...) to expressions over
    the source columns; it extends or overrides the preset's (an empty expression drops one). `session` labels every row (one
    tracker placement per file) unless a `session` column is mapped. `every` keeps every
    k-th data row (1 = all). Returns the converted text; writes it atomically to `output`.
    """
    if preset is not None and preset not in PRESETS:
        _fail(f"unknown preset '{preset}' (presets: {', '.join(PRESETS)})")
    base = PRESETS.get(preset, {}) if preset else {}
    sep = sep if sep is not None else base.get("sep", ",")
    decimal = decimal if decimal is not None else base.get("decimal", ".")
    euler = euler if euler is not None else base.get("euler")
    mapping = dict(base.get("columns", {}))
    for k, v in (columns or {}).items():
        q, _ = parse_target(k)
        # A new unit for a quantity replaces the preset's column of that quantity.
        for old in [o for o in mapping if parse_target(o)[0] == q]:
            del mapping[old]
        if v.strip():  # an empty expression drops the quantity
            mapping[k] = v
    meta = dict(base.get("metadata", {}))
    if robot:
        meta["robot"] = robot
    meta.update(metadata or {})
    if len(sep) != 1:
        _fail(f"separator must be one character, got '{sep}'")
    if decimal not in (".", ","):
        _fail(f"decimal mark must be '.' or ',', got '{decimal}'")
    if decimal == sep:
        _fail("the decimal mark and the separator are the same character")
    if every < 1:
        _fail(f"every must be >= 1, got {every}")

    # Which quantities are there, and are they complete?
    targets = {k: parse_target(k) for k in mapping}
    quantities = [q for q, _ in targets.values()]
    dup = {q for q in quantities if quantities.count(q) > 1}
    if dup:
        _fail(f"quantity mapped twice: {', '.join(sorted(dup))}")
    joints = sorted(int(_JOINT.match(q).group(1)) for q in quantities if _JOINT.match(q))
    if not joints:
        _fail("no joint columns mapped (q1_rad=COLUMN or q1_deg=COLUMN, ...)")
    if joints != list(range(1, len(joints) + 1)):
        _fail(f"joint columns must be q1..qn without gaps, got "
              f"{', '.join('q%d' % j for j in joints)}")
    for g in _GROUPS:
        have = [q for q in g if q in quantities]
        if have and len(have) != len(g):
            _fail(f"give all of {', '.join(g)} or none (have {', '.join(have)})")
    if "px" not in quantities:
        _fail("no target position mapped (px_mm=COLUMN, py_mm=..., pz_mm=...)")
    if "a" in quantities and euler not in EULER:
        _fail("orientation columns a, b, c need the Euler convention: euler xyz "
              "(R = Rx(a) Ry(b) Rz(c)) or zyx (R = Rz(a) Ry(b) Rx(c))"
              + (f", got '{euler}'" if euler else ""))
    if "session" not in quantities and not session:
        _fail("no session: give the session label (one tracker placement) or map a "
              "session column")
    if session is not None and not re.match(r"^[A-Za-z0-9_.:-]+$", session):
        _fail(f"session label '{session}' must be letters, digits, _ . : -")
    if "a" in quantities:
        meta["euler"] = euler

    path = Path(path)
    with open(path, encoding="utf-8-sig", newline="") as f:
        lines = f.read().splitlines()
    # Header: first line that is neither empty nor a comment.
    hline = next((i for i, ln in enumerate(lines) if ln.strip() and not ln.startswith("#")),
                 None)
    if hline is None:
        _fail(f"{path}: no header row")
    header = _split(lines[hline], sep)
    if len(header) < 2:
        _fail(f"{path}:{hline + 1}: header has one field; is the separator '{sep}' right?")
    exprs = {k: _Expr(v, header, f"{path}:{hline + 1}: output column '{k}'")
             for k, v in mapping.items()}

    # Output columns in the format's order.
    def order(k: str):
        q, _ = targets[k]
        m = _JOINT.match(q)
        rank = ["id", "session", "q", "px", "py", "pz", "a", "b", "c", "temp", "fx", "fy",
                "fz", "mx", "my", "mz", "sigma_p", "sigma_o"]
        return (rank.index("q"), int(m.group(1))) if m else (rank.index(q), 0)

    out_cols = sorted(mapping, key=order)
    if "id" not in mapping:
        out_cols.insert(0, "id")
    if "session" not in mapping:
        out_cols.insert(1, "session")
    joint_rad = [k for k in mapping if _JOINT.match(targets[k][0]) and targets[k][1] == "rad"]

    rows, ids, skipped, kept = [], set(), 0, 0
    for ln, text in enumerate(lines[hline + 1:], start=hline + 2):
        if not text.strip() or text.startswith("#"):
            continue
        kept += 1
        if (kept - 1) % every:
            skipped += 1
            continue
        fields = _split(text, sep)
        if len(fields) != len(header):
            _fail(f"{path}:{ln}: {len(fields)} fields, the header has {len(header)} "
                  f"(separator '{sep}')")

        def number(ci: int, fields=fields, ln=ln) -> str:
            s = fields[ci]
            if s == "":
                _fail(f"{path}:{ln}:{ci + 1}: column '{header[ci]}' is empty")
            t = s.replace(",", ".") if decimal == "," else s
            if decimal == "." and "," in s and sep != ",":
                _fail(f"{path}:{ln}:{ci + 1}: column '{header[ci]}': '{s}' has a decimal comma "
                      f"(use the decimal comma option)")
            try:
                v = float(t)
            except ValueError:
                _fail(f"{path}:{ln}:{ci + 1}: column '{header[ci]}': '{s}' is not a number")
            if not math.isfinite(v):
                _fail(f"{path}:{ln}:{ci + 1}: column '{header[ci]}': '{s}' is not finite")
            return t

        row = {}
        for k, e in exprs.items():
            if k in ("id", "session"):
                v = fields[e.cols[0]] if e.kind == "copy" else None
                if v is None:
                    _fail(f"{path}:{hline + 1}: {k} must be one column, got '{e.text}'")
                if v == "":
                    _fail(f"{path}:{ln}:{e.cols[0] + 1}: column '{header[e.cols[0]]}' "
                          f"({k}) is empty")
                row[k] = v
            else:
                row[k] = e.value(fields, number)
        for k in joint_rad:
            if abs(float(row[k])) > 4 * math.pi:
                _fail(f"{path}:{ln}: {k} = {row[k]} rad is more than two turns: degrees "
                      f"given as radians? (map it as {targets[k][0]}_deg)")
        if "session" not in row:
            row["session"] = session
        if "id" not in row:
            row["id"] = f"{row['session']}-{kept}"
        elif id_prefix or session:
            row["id"] = f"{id_prefix or session}-{row['id']}"
        if row["id"] in ids:
            _fail(f"{path}:{ln}: duplicate id '{row['id']}'")
        ids.add(row["id"])
        rows.append(row)
    if not rows:
        _fail(f"{path}: no data rows")

    def quote(s: str) -> str:
        return f'"{s}"' if ("," in s or '"' in s) else s

    meta.setdefault("imported_from", path.name)
    if every > 1:
        meta["subsampled"] = f"every {every}th row of {kept}"
    if command:
        meta["import"] = command
    out = [f"# {k}: {v}" for k, v in meta.items()]
    out.append(",".join(out_cols))
    out += [",".join(quote(r[c]) for c in out_cols) for r in rows]
    text = "\n".join(out) + "\n"
    if output is not None:
        from .cli.common import atomic_write_text

        atomic_write_text(output, text)
    return ImportResult(rows=len(rows), columns=out_cols, text=text, skipped=skipped,
                        metadata=meta)


def parse_mapping(items: Sequence[str]) -> dict[str, str]:
    """`['px_mm=x_t + x_dif', ...]` -> dict; an item without '=' is an error."""
    out = {}
    for it in items:
        if "=" not in it:
            _fail(f"column mapping '{it}' must be OUTPUT=EXPRESSION, e.g. px_mm=X")
        k, v = it.split("=", 1)
        out[k.strip()] = v.strip()
    return out


def command_line(argv: Sequence[str]) -> str:
    """The command as a user would type it, for the file's metadata."""
    return " ".join(shlex.quote(a) for a in argv)
