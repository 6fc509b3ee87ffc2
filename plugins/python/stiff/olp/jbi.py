"""Yaskawa Motoman JBI jobs (docs/olp.md): Cartesian position data C<n> under ///RECTAN with
the ///RCONF flags and frame (///POSTYPE, ///USER, ///TOOL) in effect, moved to by MOVJ, MOVL,
MOVC, MOVS in //INST."""
from __future__ import annotations

import os
import re
from typing import Optional

import numpy as np

from . import frames as fr
from .program import FilterError, Program, Target, format_numbers, parse_numbers

NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_POS = re.compile(r"^(C\d+)\s*=\s*(.*?)\s*$")
_MOVE = re.compile(r"^\s*(MOVJ|MOVL|MOVC|MOVS)\s+(C\d+)\b(.*)$")
_SPEED = re.compile(r"\bV\s*=\s*(" + NUM + ")")


class JbiFormat:
    name = "Yaskawa JBI"

    @staticmethod
    def pose_of(t: Target, values=None) -> np.ndarray:
        # Rx, Ry, Rz about the fixed axes: R = Rz Ry Rx, as Fanuc's W, P, R.
        return fr.fanuc_to_pose(*(values if values is not None else t.values)[:6])

    @staticmethod
    def values_of(pose: np.ndarray, t: Target) -> list:
        return fr.pose_to_fanuc(pose, t.values) + list(t.values[6:])

    @staticmethod
    def format_values(t: Target, values, min_decimals: int) -> list:
        return format_numbers(t, values, min_decimals)

    @staticmethod
    def parse_values(t: Target, texts) -> list:
        return parse_numbers(t, texts)

    @staticmethod
    def rconf(c) -> tuple:
        v = c.vendor_deg
        return (0 if v[4] > 0 else 1, 0 if c.elbow_up else 1, 0 if c.front else 1,
                int(abs(v[3]) >= 180), int(abs(v[5]) >= 180), int(abs(v[0]) >= 180))

    @classmethod
    def config_key(cls, c) -> tuple:
        return cls.rconf(c)[:3]

    @staticmethod
    def key_text(key) -> str:
        return "RCONF " + ",".join(str(k) for k in key)

    @classmethod
    def config_matches(cls, t: Target, c) -> bool:
        return tuple(t.config) == cls.rconf(c)

    @staticmethod
    def config_text(t: Target) -> str:
        return "RCONF " + ",".join(str(k) for k in t.config)

    @classmethod
    def config_replacements(cls, t: Target, c) -> list:
        if cls.rconf(c) != tuple(t.config):
            # the ///RCONF line holds for every position after it: not this target's alone
            raise FilterError(f"{t.name}: the compensated joints need RCONF "
                              f"{','.join(map(str, cls.rconf(c)))}, the shared ///RCONF line "
                              f"says {','.join(map(str, t.config))}")
        return []


def read_jbi(path, *, uframes: Optional[dict] = None, utools: Optional[dict] = None) -> Program:
    """Parse a JBI job. uframes/utools: {n: 4 x 4} user and tool frames of the controller
    (///USER n, ///TOOL n); POSTYPE ROBOT and BASE are the robot base frame."""
    path = os.fspath(path)
    with open(path, newline="", encoding="latin-1") as f:
        text = f.read()
    uframes, utools = uframes or {}, {0: np.eye(4), **(utools or {})}
    points, pos, section = {}, 0, None
    user, tool, postype, rectan, rconf = None, 0, None, False, None
    moves = []
    for lineno, raw in enumerate(text.splitlines(keepends=True), start=1):
        line_start, pos = pos, pos + len(raw)
        line = raw.strip()
        where = f"{path}:{lineno}"
        if line.startswith("//") and not line.startswith("///"):
            section = line[2:].split()[0] if len(line) > 2 else ""
            continue
        if section == "POS":
            if line.startswith("///USER"):
                user = int(line.split()[1])
            elif line.startswith("///TOOL"):
                tool = int(line.split()[1])
            elif line.startswith("///POSTYPE"):
                postype = line.split()[1]
            elif line.startswith("///RECTAN"):
                rectan = True
            elif line.startswith("///PULSE"):
                rectan = False
            elif line.startswith("///RCONF"):
                try:
                    rconf = tuple(int(v) for v in line.split(None, 1)[1].split(","))[:6]
                except (IndexError, ValueError):
                    raise FilterError(f"{where}: RCONF: expected integers")
            else:
                m = _POS.match(raw.rstrip("\r\n"))
                if not m:
                    continue
                name = m.group(1)
                if not rectan:
                    points[name] = (lineno, None)
                    continue
                nums = list(re.finditer(NUM, m.group(2)))
                if len(nums) < 6:
                    raise FilterError(f"{where}: {name}: expected X,Y,Z,Rx,Ry,Rz[,Re]")
                if postype == "USER":
                    if user not in uframes:
                        raise FilterError(f"{where}: {name} is in user frame {user}: give it "
                                          f"(--frame {user}=x,y,z,rx,ry,rz)")
                    base = uframes[user]
                elif postype in ("ROBOT", "BASE"):
                    base = np.eye(4)
                else:
                    raise FilterError(f"{where}: {name}: POSTYPE {postype} is not supported "
                                      "(ROBOT, BASE, USER)")
                if tool not in utools:
                    raise FilterError(f"{where}: {name} uses tool {tool}: give it "
                                      f"(--tool {tool}=x,y,z,rx,ry,rz)")
                off = line_start + m.start(2)
                spans = [("jbi", off + n.start(), off + n.end()) for n in nums]
                points[name] = (lineno, ([float(n.group(0)) for n in nums], spans, base,
                                         utools[tool], rconf))
        elif section == "INST":
            m = _MOVE.match(raw)
            if m:
                sp = _SPEED.search(m.group(3))
                moves.append((lineno, m.group(1), m.group(2), float(sp.group(1)) * fr.MM
                              if sp else None))
    targets = []
    for lineno, kind, name, speed in moves:
        where = f"{path}:{lineno}"
        if name not in points:
            raise FilterError(f"{where}: {kind} {name}: no such position in //POS")
        dline, data = points[name]
        if data is None:
            raise FilterError(f"{path}:{dline}: {name}: pulse positions need the encoder "
                              "resolution of the axes and are not supported (use RECTAN)")
        vals, spans, base, tl, conf = data
        t = Target("jbi", lineno, name, kind, kind != "MOVJ", False, vals, spans[:6], base, tl,
                   None, config=conf, speed=speed, decl_line=dline, decl_file="jbi")
        t.program_text = {"jbi": text}
        targets.append(t)
    return Program(JbiFormat(), {"jbi": path}, {"jbi": text}, targets)
