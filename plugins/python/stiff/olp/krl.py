"""KUKA KRL programs: a .src file and its .dat (docs/olp.md, section KRL)."""
from __future__ import annotations

import math
import os
import re
from typing import Optional

import numpy as np

from . import frames as fr
from .program import DecimalNumbers, FilterError, Program, Target, ToolLoad

NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_PAIR = re.compile(r"([A-Za-z_][A-Za-z0-9_]*)\s+('B[01]+'|" + NUM + ")")
_MOTION = re.compile(r"^\s*(PTP|LIN|CIRC|SPTP|SLIN|SCIRC|SPL|PTP_REL|LIN_REL|CIRC_REL)\b\s*(.*)$",
                     re.IGNORECASE)
_DECL = re.compile(r"\bDECL\s+(?:GLOBAL\s+)?(E6POS|POS|FRAME|E6AXIS|AXIS|LOAD)\s+(\w+)\s*=\s*\{",
                   re.IGNORECASE)
_ASSIGN = re.compile(r"^\s*\$(BASE|TOOL|LOAD)\s*=\s*(.*)$", re.IGNORECASE)
_BAS = re.compile(r"\bBAS\s*\(\s*#(TOOL|BASE)\s*,\s*(\d+)\s*\)", re.IGNORECASE)
_VEL = re.compile(r"^\s*\$VEL\.CP\s*=\s*(" + NUM + ")", re.IGNORECASE)
_CART = ["X", "Y", "Z", "A", "B", "C"]
_AXES = ["A1", "A2", "A3", "A4", "A5", "A6"]


def _code(line: str) -> str:
    """The line without its ';' comment (KRL has no ';' inside the statements used here)."""
    i = line.find(";")
    return line if i < 0 else line[:i]


def _aggregate(text: str, start: int) -> tuple[int, dict]:
    """Parse the aggregate whose '{' is at text[start]: (end index after '}', {KEY: (value
    text, start, end)}) of its top-level NAME value pairs (nested aggregates skipped but
    returned as KEY: ('{...}', s, e))."""
    depth, i = 0, start
    while i < len(text):
        if text[i] == "{":
            depth += 1
        elif text[i] == "}":
            depth -= 1
            if depth == 0:
                break
        elif text[i] == "\n":
            raise FilterError("aggregate not closed on its line")
        i += 1
    else:
        raise FilterError("aggregate not closed")
    body_start = start + 1
    body = text[body_start:i]
    colon = re.match(r"\s*\w+\s*:", body)  # {E6POS: X 1, ...}
    off = colon.end() if colon else 0
    out = {}
    j = off
    while j < len(body):
        m = re.compile(r"\s*([A-Za-z_][A-Za-z0-9_]*)\s+").match(body, j)
        if not m:
            j += 1
            continue
        key = m.group(1).upper()
        k = m.end()
        if k < len(body) and body[k] == "{":
            end, _ = _aggregate(text, body_start + k)
            out[key] = (text[body_start + k:end], body_start + k, end)
            j = end - body_start
        else:
            v = re.compile(r"'B[01]+'|" + NUM).match(body, k)
            if not v:
                raise FilterError(f"aggregate field {key}: not a number")
            out[key] = (v.group(0), body_start + v.start(), body_start + v.end())
            j = v.end()
        c = body.find(",", j)
        if c < 0:
            break
        j = c + 1
    return i + 1, out


def _num(v: str) -> float:
    return float(v)


def _frame(fields: dict, where: str) -> np.ndarray:
    miss = [k for k in _CART if k not in fields]
    if miss:
        raise FilterError(f"{where}: frame without {', '.join(miss)}")
    return fr.kuka_to_pose(*[_num(fields[k][0]) for k in _CART])


def _load(fields: dict, text: str, where: str) -> ToolLoad:
    if "M" not in fields:
        raise FilterError(f"{where}: load data without mass M")
    m = _num(fields["M"][0])
    cog = np.zeros(3)
    if "CM" in fields:
        _, cm = _aggregate(text, fields["CM"][1])
        cog = np.array([_num(cm[k][0]) if k in cm else 0.0 for k in "XYZ"]) * fr.MM
    if m < 0:
        raise FilterError(f"{where}: negative load mass {m}")
    return ToolLoad(m, cog)


class KrlFormat(DecimalNumbers):
    name = "KUKA KRL"

    # ---------------------------------------------------------------- numbers
    @staticmethod
    def pose_of(t: Target, values=None) -> np.ndarray:
        return fr.kuka_to_pose(*(values if values is not None else t.values))

    @staticmethod
    def values_of(pose: np.ndarray, t: Target) -> list:
        return fr.pose_to_kuka(pose, t.values)

    # ---------------------------------------------------------- configuration
    @staticmethod
    def config_key(c) -> tuple:
        """The arm configuration (Status bits); Turn is recomputed, not compared."""
        return (c.kuka_status() & 7,)

    @staticmethod
    def key_text(key) -> str:
        return f"Status {key[0]:03b}"

    @staticmethod
    def config_matches(t: Target, c) -> bool:
        s, tt = t.config
        return (s is None or (s & 7) == (c.kuka_status() & 7)) and (tt is None or tt == c.kuka_turn())

    @staticmethod
    def config_text(t: Target) -> str:
        s, tt = t.config
        return f"S {s}, T {tt}"

    @staticmethod
    def config_replacements(t: Target, c) -> list:
        """S keeps its bits above the three arm bits; T its bits above the six axes."""
        out = []
        for (f, a, b), value, mask in zip(t.config_spans, (c.kuka_status(), c.kuka_turn()),
                                          (7, 63)):
            if f is None:
                continue
            old = t.program_text[f][a:b]
            binary = old.startswith("'B")
            old_v = int(old[2:-1], 2) if binary else int(float(old))
            v = (old_v & ~mask) | (value & mask)
            new = "'B" + format(v, f"0{len(old) - 3}b") + "'" if binary else str(v)
            out.append((f, a, b, new))
        return out


def _parse_config(fields: dict, key: str) -> tuple:
    s = tt = None
    spans = [(None, 0, 0), (None, 0, 0)]
    for i, name in enumerate(("S", "T")):
        if name in fields:
            v, a, b = fields[name]
            val = int(v[2:-1], 2) if v.startswith("'B") else int(float(v))
            if i == 0:
                s = val
            else:
                tt = val
            spans[i] = (key, a, b)
    return (s, tt), spans


def read_krl(src_path, *, base_data: Optional[dict] = None, tool_data: Optional[dict] = None,
             load_data: Optional[dict] = None) -> Program:
    """Parse a .src file and the .dat beside it (same stem, if present). base_data/tool_data:
    {n: 4 x 4} for BASE_DATA[n] / TOOL_DATA[n] (they live in the controller's $config.dat);
    load_data: {n: ToolLoad} for LOAD_DATA[n]."""
    src_path = os.fspath(src_path)
    stem, _ = os.path.splitext(src_path)
    paths, texts = {"src": src_path}, {}
    for ext in (".dat", ".DAT"):
        if os.path.exists(stem + ext):
            paths["dat"] = stem + ext
            break
    for k, p in paths.items():
        with open(p, newline="", encoding="latin-1") as f:
            texts[k] = f.read()
    base_data, tool_data, load_data = base_data or {}, tool_data or {}, load_data or {}
    decls = {}
    for key in ("dat", "src"):
        if key not in texts:
            continue
        text = texts[key]
        for m in _DECL.finditer(text):
            line = text.count("\n", 0, m.start()) + 1
            try:
                _, fields = _aggregate(text, m.end() - 1)
            except FilterError as e:
                raise FilterError(f"{paths[key]}:{line}: {e}")
            decls[m.group(2).upper()] = (m.group(1).upper(), key, line, fields)

    def lookup(ref: str, table: dict, kind: str, where: str):
        mm = re.match(r"\s*(BASE_DATA|TOOL_DATA|LOAD_DATA)\[(\d+)\]", ref, re.IGNORECASE)
        if mm:
            n = int(mm.group(2))
            option = {"base": "frame"}.get(kind, kind)
            if n not in table:
                raise FilterError(f"{where}: {mm.group(1).upper()}[{n}] is defined in the "
                                  f"controller's $config.dat: give it (--{option} {n}=...)")
            return table[n]
        return None

    text = texts["src"]
    base, tool, load, speed = np.eye(4), np.eye(4), None, None
    targets = []
    pos = 0
    for lineno, raw in enumerate(text.splitlines(keepends=True), start=1):
        line_start, pos = pos, pos + len(raw)
        try:
            code = _code(raw)
            where = f"{src_path}:{lineno}"
            if not code.strip():
                continue
            m = _VEL.match(code)
            if m:
                speed = float(m.group(1))
            for b in _BAS.finditer(code):
                n = int(b.group(2))
                if b.group(1).upper() == "BASE":
                    base = lookup(f"BASE_DATA[{n}]", base_data, "base", where)
                else:
                    tool = lookup(f"TOOL_DATA[{n}]", tool_data, "tool", where)
                    load = load_data.get(n, load)
            m = _ASSIGN.match(code)
            if m:
                what, rhs = m.group(1).upper(), m.group(2).strip()
                table = {"BASE": base_data, "TOOL": tool_data, "LOAD": load_data}[what]
                value = lookup(rhs, table, what.lower(), where)
                if value is None:
                    if rhs.startswith("{"):
                        _, fields = _aggregate(text, line_start + raw.index("{"))
                    elif rhs.split(":")[0].strip().upper() in decls:
                        fields = decls[rhs.split(":")[0].strip().upper()][3]
                    elif what == "BASE" and rhs.upper().startswith("$NULLFRAME"):
                        fields = None
                    else:
                        raise FilterError(f"{where}: ${what} = {rhs}: only aggregates, declared "
                                          f"variables and {what}_DATA[n] are understood")
                    if what == "LOAD":
                        value = _load(fields, text, where)
                    else:
                        value = np.eye(4) if fields is None else _frame(fields, where)
                if what == "BASE":
                    base = value
                elif what == "TOOL":
                    tool = value
                else:
                    load = value
                continue
            m = _MOTION.match(code)
            if not m:
                continue
            kind = m.group(1).upper()
            if kind.endswith("_REL"):
                raise FilterError(f"{where}: {kind}: relative motions are not supported (their "
                                  "target depends on where the robot is)")
            args = m.group(2)
            arg_start = line_start + raw.index(args) if args else line_start
            # Targets: aggregates or variable names, one (PTP/LIN) or two (CIRC).
            items, i = [], 0
            while i < len(args) and len(items) < (2 if "CIRC" in kind else 1):
                if args[i].isspace() or args[i] == ",":
                    i += 1
                    continue
                if args[i] == "{":
                    end, fields = _aggregate(text, arg_start + i)
                    items.append(("inline", "src", lineno, fields))
                    i = end - arg_start
                    continue
                w = re.match(r"[A-Za-z_$][A-Za-z0-9_]*", args[i:])
                if not w:
                    raise FilterError(f"{where}: cannot read the target of {kind}")
                name = w.group(0).upper()
                if name not in decls:
                    raise FilterError(f"{where}: {kind} {w.group(0)}: no declaration of "
                                      f"{w.group(0)} in the .src or .dat")
                t_kind, key, dline, fields = decls[name]
                items.append((w.group(0), key, dline, fields))
                i += len(w.group(0))
            for label, key, dline, fields in items:
                cart = all(k in fields for k in _CART)
                joint = all(k in fields for k in _AXES)
                if not cart and not joint:
                    present = [k for k in _CART if k in fields]
                    raise FilterError(f"{paths[key]}:{dline}: target {label}: "
                                      + ("partial position aggregates are not supported (missing "
                                         + ", ".join(k for k in _CART if k not in fields) + ")"
                                         if present else "neither X..C nor A1..A6"))
                names = _CART if cart else _AXES
                vals = [_num(fields[k][0]) for k in names]
                spans = [(key, fields[k][1], fields[k][2]) for k in names]
                config, cspans = _parse_config(fields, key) if cart else ((None, None), [])
                t = Target(file=key, line=lineno, name=label, motion=kind,
                           process=kind in ("LIN", "CIRC", "SLIN", "SCIRC", "SPL"), joint=not cart,
                           values=vals, spans=spans, base=base, tool=tool, load=load,
                           config=None if config == (None, None) else config, config_spans=cspans,
                           speed=speed, decl_line=dline, decl_file=key)
                t.program_text = texts
                targets.append(t)
        except FilterError as e:
            if str(e).startswith(src_path):
                raise
            raise FilterError(f"{src_path}:{lineno}: {e}") from None
    return Program(KrlFormat(), paths, texts, targets)
