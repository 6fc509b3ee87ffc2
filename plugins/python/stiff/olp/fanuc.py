"""Fanuc LS programs (ASCII teach-pendant programs): /MN motion lines and /POS positions."""
from __future__ import annotations

import os
import re
from typing import Optional

import numpy as np

from . import frames as fr
from .program import DecimalNumbers, FilterError, Program, Target

NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_MOTION = re.compile(r"^\s*\d+:\s*([JLCA])\s+P\[(\d+)(?::[^\]]*)?\]\s*(?:(" + NUM +
                     r")\s*(mm/sec|cm/min|inch/min|deg/sec|%|sec|msec))?")
_CONT = re.compile(r"^\s*:\s*P\[(\d+)(?::[^\]]*)?\]\s*(?:(" + NUM + r")\s*(mm/sec|cm/min|inch/min))?")
_FRAMESEL = re.compile(r"^\s*\d+:\s*(UFRAME_NUM|UTOOL_NUM)\s*=\s*(\d+)")
_POINT = re.compile(r"^P\[(\d+)(?::[^\]]*)?\]\s*\{", re.MULTILINE)
_FIELD = re.compile(r"\b(X|Y|Z|W|P|R|J[1-9])\s*=\s*(" + NUM + r")\s*(mm|deg)")
_UFUT = re.compile(r"\bUF\s*:\s*(\d+)\s*,\s*UT\s*:\s*(\d+)")
_CONFIG = re.compile(r"CONFIG\s*:\s*'([^']*)'")
_CART = ["X", "Y", "Z", "W", "P", "R"]
_SPEED = {"mm/sec": 1e-3, "cm/min": 1e-2 / 60, "inch/min": 0.0254 / 60}


def _config(text: str, where: str) -> tuple:
    m = re.fullmatch(r"\s*([FN])\s*([UD])\s*([TB])\s*,\s*(-?\d+)\s*,\s*(-?\d+)\s*,\s*(-?\d+)\s*",
                     text)
    if not m:
        raise FilterError(f"{where}: CONFIG '{text}': expected 'N U T, 0, 0, 0'")
    return (m.group(1), m.group(2), m.group(3), int(m.group(4)), int(m.group(5)),
            int(m.group(6)))


class FanucFormat(DecimalNumbers):
    name = "Fanuc LS"

    @staticmethod
    def pose_of(t: Target, values=None) -> np.ndarray:
        return fr.fanuc_to_pose(*(values if values is not None else t.values))

    @staticmethod
    def values_of(pose: np.ndarray, t: Target) -> list:
        return fr.pose_to_fanuc(pose, t.values)

    @staticmethod
    def config_key(c) -> tuple:
        """The arm configuration (flip, up, top); the turn numbers are recomputed."""
        return c.fanuc_config()[:3]

    @staticmethod
    def key_text(key) -> str:
        return "'" + " ".join(key) + "'"

    @staticmethod
    def config_matches(t: Target, c) -> bool:
        return tuple(t.config) == c.fanuc_config()

    @staticmethod
    def config_text(t: Target) -> str:
        f, u, tb, a, b, c = t.config
        return f"CONFIG '{f} {u} {tb}, {a}, {b}, {c}'"

    @staticmethod
    def config_replacements(t: Target, c) -> list:
        new = c.fanuc_config()
        if new == tuple(t.config):
            return []
        f, a, b = t.config_spans[0]
        return [(f, a, b, f"{new[0]} {new[1]} {new[2]}, {new[3]}, {new[4]}, {new[5]}")]


def read_ls(path, *, uframes: Optional[dict] = None, utools: Optional[dict] = None) -> Program:
    """Parse a Fanuc .ls program. uframes/utools: {n: 4 x 4} user and tool frames of the
    controller (frame 0 is the world / the flange)."""
    path = os.fspath(path)
    with open(path, newline="", encoding="latin-1") as f:
        text = f.read()
    uframes = {0: np.eye(4), **(uframes or {})}
    utools = {0: np.eye(4), **(utools or {})}
    mn = text.find("/MN")
    pos_sec = text.find("/POS")
    if mn < 0 or pos_sec < 0:
        raise FilterError(f"{path}: no /MN or /POS section")
    points = {}
    for m in _POINT.finditer(text, pos_sec):
        n = int(m.group(1))
        end = text.find("};", m.end())
        if end < 0:
            raise FilterError(f"{path}:{text.count(chr(10), 0, m.start()) + 1}: P[{n}] not closed")
        block_line = text.count("\n", 0, m.start()) + 1
        where = f"{path}:{block_line}"
        gp = text.find("GP1:", m.end(), end)
        if gp < 0:
            raise FilterError(f"{where}: P[{n}] has no GP1 group")
        nxt = text.find("GP2:", gp, end)
        gend = end if nxt < 0 else nxt
        fields = {fm.group(1): (fm.group(2), fm.start(2), fm.end(2), fm.group(3))
                  for fm in _FIELD.finditer(text, gp, gend)}
        uf = _UFUT.search(text, gp, gend)
        if not uf:
            raise FilterError(f"{where}: P[{n}] has no UF/UT")
        cm = _CONFIG.search(text, gp, gend)
        points[n] = (block_line, fields, int(uf.group(1)), int(uf.group(2)),
                     (_config(cm.group(1), where), (cm.start(1), cm.end(1))) if cm else None)
    targets = []
    pos = 0
    lines = text.splitlines(keepends=True)
    for lineno, raw in enumerate(lines, start=1):
        line_start, pos = pos, pos + len(raw)
        try:
            if line_start < mn or line_start >= pos_sec:
                continue
            where = f"{path}:{lineno}"
            fm = _FRAMESEL.match(raw)
            if fm:
                continue  # the frame numbers stored in each position decide
            m = _MOTION.match(raw)
            kind = None
            if m:
                kind, n, sp, unit = m.group(1), int(m.group(2)), m.group(3), m.group(4)
            else:
                c = _CONT.match(raw)
                if c and targets and targets[-1].motion == "C":
                    kind, n, sp, unit = "C", int(c.group(1)), c.group(2), c.group(3)
            if kind is None:
                if re.match(r"^\s*\d+:\s*[JLCA]\s+PR\[", raw):
                    raise FilterError(f"{where}: motions to position registers PR[] are not "
                                      "supported (their values live in the controller)")
                continue
            if n not in points:
                raise FilterError(f"{where}: P[{n}] is not in the /POS section")
            dline, fields, uf, ut, conf = points[n]
            if uf not in uframes:
                raise FilterError(f"{path}:{dline}: P[{n}] uses UF {uf}: give the user frame "
                                  f"(--uframe {uf}=x,y,z,w,p,r)")
            if ut not in utools:
                raise FilterError(f"{path}:{dline}: P[{n}] uses UT {ut}: give the tool frame "
                                  f"(--utool {ut}=x,y,z,w,p,r)")
            speed = float(sp) * _SPEED[unit] if sp and unit in _SPEED else None
            cart = all(k in fields for k in _CART)
            names = _CART if cart else sorted([k for k in fields if k.startswith("J")])
            if not cart and len(names) < 1:
                raise FilterError(f"{path}:{dline}: P[{n}]: neither X..R nor J1..Jn")
            vals = [float(fields[k][0]) for k in names]
            spans = [("ls", fields[k][1], fields[k][2]) for k in names]
            t = Target("ls", lineno, f"P[{n}]", kind, kind in ("L", "C"), not cart, vals, spans,
                       uframes[uf], utools[ut], None,
                       config=conf[0] if (cart and conf) else None,
                       config_spans=[("ls",) + conf[1]] if (cart and conf) else [],
                       speed=speed, decl_line=dline, decl_file="ls")
            t.program_text = {"ls": text}
            targets.append(t)
        except FilterError as e:
            if str(e).startswith(path):
                raise
            raise FilterError(f"{path}:{lineno}: {e}") from None
    return Program(FanucFormat(), {"ls": path}, {"ls": text}, targets)
