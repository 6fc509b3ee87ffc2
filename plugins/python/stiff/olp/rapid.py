"""ABB RAPID modules (.mod): robtarget, jointtarget, tooldata, wobjdata (docs/olp.md)."""
from __future__ import annotations

import os
import re

import numpy as np

from . import frames as fr
from .program import (ANGLE_EXTRA_DECIMALS, FilterError, Program, Target, ToolLoad, format_numbers,
                      parse_numbers)

NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_DECL = re.compile(r"\b(?:LOCAL\s+)?(?:CONST|PERS|VAR|TASK\s+PERS)\s+(robtarget|jointtarget|"
                   r"tooldata|wobjdata|speeddata)\s+(\w+)\s*:=\s*\[", re.IGNORECASE)
_MOVE = re.compile(r"^\s*(MoveL|MoveJ|MoveC|MoveAbsJ|MoveLDO|MoveJDO|MoveLSync|MoveJSync)\b\s*"
                   r"(.*?);", re.IGNORECASE)
_LEAF = re.compile(r'"[^"]*"|' + NUM + r"|[A-Za-z_][A-Za-z0-9_]*")


def _code(line: str) -> str:
    i = line.find("!")
    return line if i < 0 else line[:i]


def _brackets(text: str, start: int):
    """Parse the RAPID aggregate whose '[' is at text[start]: (end, tree); a tree is a list of
    trees and leaves (text, a, b)."""
    assert text[start] == "["
    stack, i = [[]], start + 1
    while i < len(text):
        ch = text[i]
        if ch == "[":
            stack.append([])
            i += 1
        elif ch == "]":
            done = stack.pop()
            i += 1
            if not stack:
                return i, done
            stack[-1].append(done)
        elif ch in ", \t\r\n":
            i += 1
        else:
            m = _LEAF.match(text, i)
            if not m:
                raise FilterError(f"unexpected '{ch}' in an aggregate")
            stack[-1].append((m.group(0), m.start(), m.end()))
            i = m.end()
    raise FilterError("aggregate not closed")


def _nums(tree, what: str) -> list:
    try:
        return [float(leaf[0]) for leaf in tree]
    except (TypeError, ValueError, IndexError):
        raise FilterError(f"{what}: expected numbers")


def _pose(tree, what: str) -> np.ndarray:
    if (not isinstance(tree, list) or len(tree) != 2 or not isinstance(tree[0], list)
            or not isinstance(tree[1], list) or len(tree[0]) != 3 or len(tree[1]) != 4):
        raise FilterError(f"{what}: expected [[x,y,z],[q1,q2,q3,q4]]")
    try:
        return fr.abb_to_pose(_nums(tree[0], what), _nums(tree[1], what))
    except ValueError as e:
        raise FilterError(f"{what}: {e}")


class RapidFormat:
    name = "ABB RAPID"

    @staticmethod
    def pose_of(t: Target, values=None) -> np.ndarray:
        v = values if values is not None else t.values
        return fr.abb_to_pose(v[:3], v[3:7])

    @staticmethod
    def values_of(pose: np.ndarray, t: Target) -> list:
        xyz, q = fr.pose_to_abb(pose, t.values[3:7])
        return xyz + q

    @staticmethod
    def format_values(t: Target, values, min_decimals: int) -> list:
        # quaternion components (from the fourth number) and joint angles get more decimals
        return format_numbers(t, values, min_decimals,
                              lambda i: ANGLE_EXTRA_DECIMALS if (i >= 3 or t.joint) else 0)

    @staticmethod
    def parse_values(t: Target, texts) -> list:
        return parse_numbers(t, texts)

    @staticmethod
    def config_key(c) -> tuple:
        """The arm configuration (cfx); the quadrants cf1, cf4, cf6 are recomputed."""
        return (c.abb_confdata()[3],)

    @staticmethod
    def key_text(key) -> str:
        return f"cfx {key[0]}"

    @staticmethod
    def config_matches(t: Target, c) -> bool:
        return list(t.config) == c.abb_confdata()

    @staticmethod
    def config_text(t: Target) -> str:
        return "confdata [" + ",".join(str(v) for v in t.config) + "]"

    @staticmethod
    def config_replacements(t: Target, c) -> list:
        return [(f, a, b, str(v)) for (f, a, b), v, old in
                zip(t.config_spans, c.abb_confdata(), t.config) if v != old]


def _speed(name_or_tree, speeds: dict):
    if isinstance(name_or_tree, list):
        return _nums(name_or_tree, "speeddata")[0] * fr.MM
    name = name_or_tree.strip()
    m = re.fullmatch(r"v(\d+)", name, re.IGNORECASE)
    if m:
        return float(m.group(1)) * fr.MM
    if name.lower() == "vmax":
        return None
    return speeds.get(name.upper())


def _split_args(text: str) -> list:
    out, depth, cur = [], 0, []
    for ch in text:
        if ch == "[":
            depth += 1
        elif ch == "]":
            depth -= 1
        if ch == "," and depth == 0:
            out.append("".join(cur))
            cur = []
        else:
            cur.append(ch)
    out.append("".join(cur))
    return out


def read_rapid(path) -> Program:
    """Parse a RAPID module: every robtarget/jointtarget a Move instruction uses (declared or
    inline), with the tooldata and wobjdata of that instruction."""
    path = os.fspath(path)
    with open(path, newline="", encoding="latin-1") as f:
        text = f.read()
    decl = {}
    for m in _DECL.finditer(text):
        line = text.count("\n", 0, m.start()) + 1
        try:
            _, tree = _brackets(text, m.end() - 1)
        except FilterError as e:
            raise FilterError(f"{path}:{line}: {e}")
        decl[m.group(2).upper()] = (m.group(1).lower(), line, tree)
    tools = {"TOOL0": (np.eye(4), None)}
    wobjs = {"WOBJ0": np.eye(4)}
    speeds = {}
    for name, (kind, line, tree) in decl.items():
        where = f"{path}:{line}"
        if kind == "tooldata":
            if len(tree) != 3 or not isinstance(tree[2], list) or len(tree[2]) < 2:
                raise FilterError(f"{where}: tooldata {name}: expected [robhold,[[x,y,z],[q]],"
                                  "[mass,[cog],[aom],ix,iy,iz]]")
            if tree[0][0].upper() == "FALSE":
                raise FilterError(f"{where}: tooldata {name}: stationary tools (robhold FALSE)"
                                  " are not supported")
            load = tree[2]
            mass = float(load[0][0])
            cog = np.array(_nums(load[1], f"{where}: tooldata cog")) * fr.MM
            tools[name] = (_pose(tree[1], f"{where}: tooldata {name}"), ToolLoad(mass, cog))
        elif kind == "wobjdata":
            if len(tree) != 5:
                raise FilterError(f"{where}: wobjdata {name}: expected 5 fields")
            if tree[0][0].upper() == "TRUE":
                raise FilterError(f"{where}: wobjdata {name}: robot-held work objects are not "
                                  "supported")
            if tree[1][0].upper() == "FALSE":
                raise FilterError(f"{where}: wobjdata {name}: work objects on a mechanical "
                                  "unit (ufprog FALSE) are not supported")
            wobjs[name] = _pose(tree[3], f"{where}: uframe") @ _pose(tree[4], f"{where}: oframe")
        elif kind == "speeddata":
            speeds[name] = _nums(tree, f"{where}: speeddata")[0] * fr.MM
    targets = []
    pos = 0
    for lineno, raw in enumerate(text.splitlines(keepends=True), start=1):
        line_start, pos = pos, pos + len(raw)
        try:
            code = _code(raw)
            m = _MOVE.match(code)
            if not m:
                continue
            where = f"{path}:{lineno}"
            inst = m.group(1)
            args_start = line_start + m.start(2)
            args = _split_args(m.group(2))
            ntarget = 2 if inst.lower() == "movec" else 1
            if len(args) < ntarget + 3:
                raise FilterError(f"{where}: {inst}: expected target, speed, zone, tool")
            positional = [re.split(r"\\", a)[0].strip() for a in args]
            tool_name = positional[ntarget + 2].upper()
            if tool_name not in tools:
                raise FilterError(f"{where}: tooldata {positional[ntarget + 2]} is not declared in "
                                  "this module")
            wm = re.search(r"\\WObj\s*:=\s*(\w+)", m.group(2), re.IGNORECASE)
            wname = wm.group(1).upper() if wm else "WOBJ0"
            if wname not in wobjs:
                raise FilterError(f"{where}: wobjdata {wm.group(1)} is not declared in this module")
            tool, load = tools[tool_name]
            base = wobjs[wname]
            sp_arg = positional[ntarget]
            speed = _speed(sp_arg, speeds)
            offset = 0
            for k in range(ntarget):
                arg = args[k]
                a_start = args_start + offset + (len(arg) - len(arg.lstrip()))
                offset += len(arg) + 1
                name = arg.strip()
                if name.startswith("["):
                    _, tree = _brackets(text, a_start)
                    label, dline, tkind = "inline", lineno, \
                        "jointtarget" if inst.lower() == "moveabsj" else "robtarget"
                else:
                    if "(" in name:
                        raise FilterError(f"{where}: {inst} {name}: computed targets (Offs, RelTool)"
                                          " are not supported")
                    if name.upper() not in decl:
                        raise FilterError(f"{where}: {inst} {name}: not declared in this module")
                    tkind, dline, tree = decl[name.upper()]
                    label = name
                if inst.lower() == "moveabsj":
                    if tkind != "jointtarget":
                        raise FilterError(f"{where}: MoveAbsJ needs a jointtarget")
                    if (not isinstance(tree, list) or len(tree) != 2 or not isinstance(tree[0], list)
                            or len(tree[0]) != 6):
                        raise FilterError(f"{path}:{dline}: {label}: expected jointtarget "
                                          "[[j1,...,j6],[eax]]")
                    leaves = tree[0]
                    vals = _nums(leaves, f"{path}:{dline}: jointtarget {label}")
                    t = Target("mod", lineno, label, inst, False, True, vals,
                               [("mod", lf[1], lf[2]) for lf in leaves], base, tool, load,
                               speed=speed, decl_line=dline, decl_file="mod")
                else:
                    if (tkind != "robtarget" or not isinstance(tree, list) or len(tree) != 4
                            or not all(isinstance(x, list) for x in tree[:3])
                            or [len(x) for x in tree[:3]] != [3, 4, 4]):
                        raise FilterError(f"{path}:{dline}: {label}: expected robtarget [[x,y,z],"
                                          "[q1,q2,q3,q4],[cf1,cf4,cf6,cfx],[eax]]")
                    leaves = list(tree[0]) + list(tree[1])
                    vals = _nums(leaves, f"{path}:{dline}: robtarget {label}")
                    _pose(tree[:2], f"{path}:{dline}: robtarget {label}")  # unit quaternion
                    try:
                        conf = [int(c[0]) for c in tree[2]]
                    except (TypeError, ValueError):
                        raise FilterError(f"{path}:{dline}: robtarget {label}: confdata must be "
                                          "four integers")
                    t = Target("mod", lineno, label, inst, inst.lower().startswith(("movel", "movec")),
                               False, vals, [("mod", lf[1], lf[2]) for lf in leaves], base, tool,
                               load, config=conf, config_spans=[("mod", c[1], c[2]) for c in tree[2]],
                               speed=speed, decl_line=dline, decl_file="mod")
                t.program_text = {"mod": text}
                targets.append(t)
        except FilterError as e:
            if str(e).startswith(path):
                raise
            raise FilterError(f"{path}:{lineno}: {e}") from None
    return Program(RapidFormat(), {"mod": path}, {"mod": text}, targets)
