"""G-code as CAM post-processors write it (tests/data/gcode: Fusion-like with a byte-order mark,
Mastercam-like with R arcs and G28, LinuxCNC-like arcs in G18/G19 and a helix). The expected
geometry is written here from the programs' words (centres, radii, turning sense), not from
the reader."""
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import stiff

GCODE = Path(__file__).resolve().parents[3] / "tests" / "data" / "gcode"
MM = 1e-3
# The reader splits arcs into chords within 1 um of the circle (docs/compensation.md).
CHORD_TOL_M = 1e-6


def _xyz(path):
    return path.poses[:, :3, 3] / MM  # mm, workpiece frame = base frame here


def _arc_points(path, line):
    return _xyz(path)[path.lines == line]


def _check_arc(points, start, centre, radius, sense, plane=(0, 1)):
    """Every point on the circle; the angle advancing in the given sense (+1 CCW). start and
    centre are (u, v) coordinates of the plane."""
    u, v = plane
    rel = points[:, [u, v]] - np.asarray(centre)
    assert np.abs(np.linalg.norm(rel, axis=1) - radius).max() < 1e-9
    ang = np.unwrap(np.concatenate([[math.atan2(start[1] - centre[1], start[0] - centre[0])],
                                    np.arctan2(rel[:, 1], rel[:, 0])]))
    steps = np.diff(ang)
    assert (sense * steps > 0).all()
    # Chord sagitta r (1 - cos(step / 2)) within the tolerance.
    assert (radius * MM * (1 - np.cos(steps / 2)) <= CHORD_TOL_M * (1 + 1e-9)).all()
    return ang[-1] - ang[0]


def test_fusion_program_with_bom_g43_and_arcs():
    text = (GCODE / "fusion_pocket.nc").read_bytes()
    assert text.startswith(b"\xef\xbb\xbf")
    p = stiff.read_path(GCODE / "fusion_pocket.nc")
    xyz = _xyz(p)
    lines = (GCODE / "fusion_pocket.nc").read_text(encoding="utf-8-sig").splitlines()
    line_of = lambda word: 1 + next(i for i, l in enumerate(lines) if l.startswith(word + " "))
    # No invented first point: "G53 G0 Z0." goes home, "G0 X20. Y15." leaves Z unknown; the
    # first point is where G43 brings Z (X20 Y15 Z15).
    assert p.lines[0] == line_of("N50") and np.allclose(xyz[0], [20, 15, 15])
    # G0 rows are rapid, the rest are not.
    assert p.rapid[0] and p.rapid[p.lines == line_of("N55")].all()
    assert not p.rapid[p.lines == line_of("N70")].any()
    # G3 semicircle about (21.5, 15), then quarter arcs, then a full circle about (20, 20).
    sweep = _check_arc(_arc_points(p, line_of("N70")), (20, 15), (21.5, 15), 1.5, +1)
    assert sweep == pytest.approx(math.pi)
    assert _check_arc(_arc_points(p, line_of("N80")), (30, 15), (30, 20), 5, +1) == pytest.approx(math.pi / 2)
    full = _arc_points(p, line_of("N120"))
    assert _check_arc(full, (20, 15), (20, 20), 5, +1) == pytest.approx(2 * math.pi)
    assert np.allclose(full[-1], [20, 15, -1])
    # G53 after the last move is not a point: the program ends at the G0 Z15.
    assert p.lines[-1] == line_of("N125")


def test_mastercam_program_with_r_arcs_rotary_zero_and_g28():
    p = stiff.read_path(GCODE / "mastercam_contour.nc")
    lines = (GCODE / "mastercam_contour.nc").read_text().splitlines()
    line_of = lambda text: 1 + lines.index(text)
    xyz = _xyz(p)
    assert np.allclose(xyz[0], [0, 0, 25]) and p.lines[0] == line_of("G43 H1 Z25.")
    # Corners: clockwise quarter arcs (G2), centres from I/J or from the short-arc rule of R > 0.
    for text, start, centre in (("G2 X10. Y60. I10. J0.", (0, 50), (10, 50)),
                                ("G2 X100. Y50. R10.", (90, 60), (90, 50)),
                                ("G2 X90. Y0. I-10. J0.", (100, 10), (90, 10)),
                                ("G2 X0. Y10. R10.", (10, 0), (10, 10))):
        assert _check_arc(_arc_points(p, line_of(text)), start, centre, 10, -1) == pytest.approx(-math.pi / 2)
    # R < 0: the long way round (270 deg counter-clockwise about the origin).
    assert _check_arc(_arc_points(p, line_of("G3 X10. Y0. R-10.")), (0, 10), (0, 0), 10, +1) == pytest.approx(1.5 * math.pi)
    # "G91 G28 Z0." goes home: not a point; the path ends at G0 Z25.
    assert p.lines[-1] == line_of("G0 Z25.") and np.allclose(xyz[-1], [10, 0, 25])


def test_linuxcnc_arcs_in_zx_and_yz_planes_and_helix():
    p = stiff.read_path(GCODE / "linuxcnc_planes.ngc")
    xyz = _xyz(p)
    # G18: plane (Z, X), counter-clockwise seen from +Y, about (z, x) = (0, 10): over the top.
    bead = xyz[p.lines == 6]
    _check_arc(bead, (0, 0), (0, 10), 10, +1, plane=(2, 0))
    assert bead[:, 2].max() == pytest.approx(10, abs=1e-3) and (bead[:, 1] == 0).all()
    # G19 helix: plane (Y, Z) about (y, z) = (0, 10), X from 20 to 25 in proportion to the angle.
    helix = xyz[p.lines == 7]
    sweep = _check_arc(helix, (0, 0), (0, 10), 10, +1, plane=(1, 2))
    assert sweep == pytest.approx(math.pi / 2)
    ang = np.arctan2(helix[:, 2] - 10, helix[:, 1]) + math.pi / 2
    assert np.allclose(helix[:, 0], 20 + 5 * ang / (math.pi / 2), atol=1e-9)
    # G17 full circle, clockwise.
    circle = xyz[p.lines == 8]
    assert _check_arc(circle, (25, 10), (30, 10), 5, -1) == pytest.approx(-2 * math.pi)


def test_segment_option_bounds_arc_pieces():
    p = stiff.read_path(GCODE / "mastercam_contour.nc", segment_m=0.5e-3)
    xyz = _xyz(p)
    steps = np.linalg.norm(np.diff(xyz, axis=0), axis=1)
    feed = ~p.rapid[1:]
    assert steps[feed].max() <= 0.5 + 1e-9


@pytest.mark.parametrize("program, line, message", [
    ("G21 G90\nG0 X0 Y0 Z5\nG1 X10 A30. F100\n", 3, "rotary axis word 'A30.'"),
    ("G0 X0 Y0 Z0\nG2 X1 Y2 I1 J0 F10\n", 2, "arc end point is not on the circle"),
    ("G0 X0 Y0 Z0\nG2 X30 Y0 R10 F10\n", 2, "farther from the start than the diameter"),
    ("G0 X0 Y0 Z0\nG2 X1 Y1 I1 J0 R1 F10\n", 2, "not both"),
    ("G91\nG0 X10 Y0 Z0\n", 2, "incremental move (G91) before the position is known"),
    ("G0 X0 Y0\nG2 X10 Y0 I5 J0 F100\n", 2, "arc before the position is known"),
])
def test_bad_programs_name_line_and_reason(tmp_path, program, line, message):
    f = tmp_path / "bad.nc"
    f.write_text(program)
    with pytest.raises(stiff.ParseError) as e:
        stiff.read_path(f)
    assert e.value.line == line and message in str(e.value)
    if "rotary" in message:
        assert "--tool-rpy" in str(e.value)
