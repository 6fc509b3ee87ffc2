"""`stiff import` on the shipped real data and on bad tracker exports."""
import math
import subprocess
import sys

import pytest

from stiff import importer
from stiff.importer import ImportFormatError, import_table


def _rows(path):
    lines = [ln for ln in open(path).read().splitlines() if ln and not ln.startswith("#")]
    header = lines[0].split(",")
    return header, [dict(zip(header, ln.split(","))) for ln in lines[1:]]


def _meta(path):
    return dict(ln[2:].split(": ", 1) for ln in open(path).read().splitlines()
                if ln.startswith("# "))


def test_shipped_files_have_their_rows(root):
    real = root / "examples" / "real"
    counts = {"ur5/ur5_grid.csv": 1000, "ur5/ur5_random.csv": 20,
              "ur10/ur10_C_random_poses.csv": 2773, "ur10/ur10_B_joint_configurations.csv": 1495,
              "ur10/ur10_D_iso_cubes.csv": 632, "ur10/ur10_A_grid.csv": 2383}
    for name, n in counts.items():
        header, rows = _rows(real / name)
        assert len(rows) == n, name
        assert len({r["id"] for r in rows}) == n
        assert {"session", "q1_rad" if "ur10" in name else "q1_deg", "px_mm", "pz_mm"} <= set(header)
    assert _meta(real / "ur10/ur10_C_random_poses.csv")["euler"] == "xyz"


def _write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text)
    return p


UR5_HEAD = "step_order,x_t,y_t,z_t,x_dif,y_dif,z_dif,joint_1,joint_2,joint_3,joint_4,joint_5,joint_6\n"
UR5_ROW = ("0,-430.32784075885013,-6.2740647628546,-98.6368469428076,-2.144122241149887,"
           "-3.5212622371454003,0.8144149428075877,-22.933297010882566,-43.71915584236375,"
           "135.39784676276338,-94.74032099477175,55.416784894781806,-5.552224723991238\n")


def test_jacobi_row_converted_exactly(tmp_path):
    src = _write(tmp_path, "grid.csv", UR5_HEAD + UR5_ROW)
    out = tmp_path / "out.csv"
    res = import_table(src, out, preset="jacobi2025", session="ur5", id_prefix="grid")
    assert res.rows == 1
    _, rows = _rows(out)
    r = rows[0]
    assert r["id"] == "grid-0" and r["session"] == "ur5"
    assert r["q2_deg"] == "-43.71915584236375"  # copied as text
    # measured = target + error, to the last bit of the double sum
    assert float(r["px_mm"]) == -430.32784075885013 + -2.144122241149887
    assert float(r["py_mm"]) == -6.2740647628546 + -3.5212622371454003
    assert float(r["pz_mm"]) == -98.6368469428076 + 0.8144149428075877
    assert _meta(out)["robot"] == "ur5"


def test_shipped_ur5_first_row_is_target_plus_error(root):
    _, rows = _rows(root / "examples/real/ur5/ur5_grid.csv")
    assert rows[0]["q1_deg"] == "-22.933297010882566"
    assert float(rows[0]["px_mm"]) == -430.32784075885013 + -2.144122241149887


LG_HEAD = ("Timestamp;Goal x;Goal y;Goal z;Goal roll;Goal pitch;Goal yaw;shoulder_pan_joint;"
           "shoulder_lift_joint;elbow_joint;wrist_1_joint;wrist_2_joint;wrist_3_joint;"
           "measurement_temperature;measurement_x;measurement_std_x;measurement_y;"
           "measurement_std_y;measurement_z;measurement_std_z;measurement_rx;measurement_std_rx;"
           "measurement_ry;measurement_std_ry;measurement_rz;measurement_std_rz\n")
LG_ROW = ("2,02011E+13;0,0103459;-0,480444;1,00632;3,10253;1,66683;1,57927;-4,08444;-2,6946;"
          "1,69873;-2,031;0,99275;-0,0673035;21,68000031;335,14778;0,0054521;-3134,3677;"
          "0,0062093;-221,16088;0,0076535;-84,20352;0,00099888;-22,726835;0,0026542;"
          "-88,245609;0,0014716\n")


def test_landgraf_row_converted_exactly(tmp_path):
    src = _write(tmp_path, "c.csv", LG_HEAD + LG_ROW + LG_ROW)
    out = tmp_path / "c_out.csv"
    import_table(src, out, preset="landgraf2021", session="C")
    header, rows = _rows(out)
    assert len(rows) == 2 and rows[0]["id"] == "C-1" and rows[1]["id"] == "C-2"
    r = rows[0]
    assert (r["q1_rad"], r["q6_rad"]) == ("-4.08444", "-0.0673035")
    assert (r["px_mm"], r["py_mm"], r["pz_mm"]) == ("335.14778", "-3134.3677", "-221.16088")
    assert (r["a_deg"], r["b_deg"], r["c_deg"]) == ("-84.20352", "-22.726835", "-88.245609")
    assert r["temp_C"] == "21.68000031"
    s = math.sqrt((0.0054521 ** 2 + 0.0062093 ** 2 + 0.0076535 ** 2) / 3)
    assert float(r["sigma_p_mm"]) == pytest.approx(s, rel=1e-5)
    assert _meta(out)["euler"] == "xyz"
    assert "Goal x" not in header


def test_shipped_ur10_C_first_row(root):
    _, rows = _rows(root / "examples/real/ur10/ur10_C_random_poses.csv")
    r = rows[1]
    assert (r["id"], r["session"]) == ("C-2", "C")
    assert (r["px_mm"], r["a_deg"], r["q1_rad"]) == ("335.14778", "-84.20352", "-4.08444")


def _err(tmp_path, text, **kw):
    src = _write(tmp_path, "bad.csv", text)
    out = tmp_path / "never.csv"
    with pytest.raises(ImportFormatError) as e:
        import_table(src, out, **kw)
    assert not out.exists()  # nothing half written
    return str(e.value)


def test_bad_inputs_name_file_and_line(tmp_path):
    kw = dict(preset="jacobi2025", session="s")
    m = _err(tmp_path, UR5_HEAD + UR5_ROW + UR5_ROW.replace("-43.71915584236375", "abc"), **kw)
    assert "bad.csv:3:9" in m and "joint_2" in m and "'abc' is not a number" in m
    m = _err(tmp_path, UR5_HEAD + UR5_ROW + "1,2,3\n", **kw)
    assert "bad.csv:3:" in m and "3 fields" in m
    m = _err(tmp_path, UR5_HEAD + UR5_ROW.replace(",-94.74032099477175", ","), **kw)
    assert "bad.csv:2:11" in m and "empty" in m
    m = _err(tmp_path, UR5_HEAD.replace("x_dif", "xdif") + UR5_ROW, **kw)
    assert "bad.csv:1" in m and "no column 'x_dif'" in m
    m = _err(tmp_path, UR5_HEAD + UR5_ROW + UR5_ROW, **kw)
    assert "bad.csv:3" in m and "duplicate id" in m
    m = _err(tmp_path, UR5_HEAD + UR5_ROW, preset="jacobi2025")
    assert "no session" in m
    m = _err(tmp_path, "", **kw)
    assert "no header" in m


def test_bad_landgraf_inputs(tmp_path):
    # decimal commas read without the option
    m = _err(tmp_path, LG_HEAD + LG_ROW, preset="landgraf2021", session="C", decimal=".")
    assert "bad.csv:2:" in m and "decimal comma" in m
    # degrees given as radians
    row = LG_ROW.replace("-4,08444", "-234,0")
    m = _err(tmp_path, LG_HEAD + row, preset="landgraf2021", session="C")
    assert "bad.csv:2" in m and "q1_rad" in m and "degrees given as radians" in m
    # orientation without a convention
    m = _err(tmp_path, LG_HEAD + LG_ROW, sep=";", decimal=",", session="C",
             columns={**{f"q{i}_rad": c for i, c in enumerate(
                 ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint",
                  "wrist_2_joint", "wrist_3_joint"], 1)},
                      "px_mm": "measurement_x", "py_mm": "measurement_y",
                      "pz_mm": "measurement_z", "a_deg": "measurement_rx",
                      "b_deg": "measurement_ry", "c_deg": "measurement_rz"})
    assert "Euler convention" in m
    # incomplete group, unknown unit
    m = _err(tmp_path, LG_HEAD + LG_ROW, preset="landgraf2021", session="C",
             columns={"pz_mm": ""})
    assert "px, py, pz" in m
    m = _err(tmp_path, LG_HEAD + LG_ROW, preset="landgraf2021", session="C",
             columns={"px_in": "measurement_x"})
    assert "unit 'in'" in m


def test_existing_output_kept_on_error(tmp_path):
    out = _write(tmp_path, "keep.csv", "precious\n")
    src = _write(tmp_path, "bad.csv", UR5_HEAD + "1,2\n")
    with pytest.raises(ImportFormatError):
        import_table(src, out, preset="jacobi2025", session="s")
    assert out.read_text() == "precious\n"


def test_cli_generic_mapping_and_subsampling(tmp_path):
    text = "J1;J2;X;Y;Z;Yaw;Pitch;Roll\n" + "".join(
        f"{i},5;{-i};{1000 + i},25;0;5;10;0;0\n" for i in range(10))
    src = _write(tmp_path, "export.csv", text)
    out = tmp_path / "cell1.csv"
    cmd = [sys.executable, "-m", "stiff.cli", "import", "--sep", ";", "--decimal-comma",
           "--euler", "zyx", "--session", "cell1", "--robot", "myarm", "--every", "3",
           "--map", "q1_deg=J1", "--map", "q2_deg=J2", "--map", "px_mm=X", "--map", "py_mm=Y",
           "--map", "pz_mm=Z", "--map", "a_deg=Yaw", "--map", "b_deg=Pitch",
           "--map", "c_deg=Roll", str(src), "-o", str(out)]
    r = subprocess.run(cmd, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    _, rows = _rows(out)
    assert [x["id"] for x in rows] == ["cell1-1", "cell1-4", "cell1-7", "cell1-10"]
    assert rows[1]["q1_deg"] == "3.5" and rows[1]["px_mm"] == "1003.25"
    meta = _meta(out)
    assert meta["euler"] == "zyx" and meta["robot"] == "myarm"
    # a user error: one line naming file:line, exit code 2, no traceback
    bad = _write(tmp_path, "bad.csv", "J1;J2;X;Y;Z\n1;2;3;4\n")
    r = subprocess.run(cmd[:-3] + [str(bad), "-o", str(tmp_path / "x.csv")],
                       capture_output=True, text=True)
    assert r.returncode == 2 and "bad.csv:" in r.stderr and "Traceback" not in r.stderr


def test_presets_are_listed():
    assert set(importer.PRESETS) == {"jacobi2025", "landgraf2021"}
