"""The bad-input catalogue (docs/reliability.md): every case is an input stiff must refuse with
a clear error, never a crash, a traceback, a NaN or a half-written file. Run by
test_bad_inputs.py; `python tests/bad_inputs/cases.py` prints the catalogue as a Markdown table.

Fields of a case:
  id       unique name (the pytest id)
  kind     "cli"    the `stiff` command line: args; expect exit code `exit` (2 for user errors),
                    one line on stderr (unless `one_line=False`: argparse usage errors) that
                    contains `message`; an existing -o target ({out}) is left untouched and no
                    *.tmp* file remains.
           "capi"   the C ABI through ctypes: `code` (a Python expression returning a status,
                    with helpers from the runner) must return `status` with `message` in
                    stiff_last_error().
           "python" the Python package: `code` must raise `error` (class name in stiff.errors
                    or a builtin) whose text contains `message`; `status` checks `.status`.
           "fmu"    an exported FMU driven with fmpy: `code` must raise an FMI error (or
                    return False) and the FMU's log must contain `message`.
  files    files written into the case's folder first: {name: text}
  topic    what kind of bad input (for the table)
Placeholders in args/code/files: {tmp} the case's folder, {data} a good measurement CSV with
displacements, {design} a plan CSV (no displacements), {fit} a good fit JSON, {robot} rokae.yaml,
{out} an existing output file that must survive, {fmu2}/{fmu3} exported FMUs.
"""

HEADER6 = "id,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,fx_N,fy_N,fz_N,dx_um,dy_um,dz_um\n"
ROW = "{id},10,-40,30,20,50,0,20,-25,30,{dx},{dy},{dz}\n"


def rows(n, same_pose=False):
    out = []
    for i in range(n):
        q = "10,-40,30,20,50,0" if same_pose else f"{10 + 7 * i},{-40 + 5 * i},{30 - 3 * i},{20 + 9 * i},{50 - 4 * i},0"
        out.append(f"m{i},{q},20,-25,30,{12 + i},{-8 + i},{5 + 2 * i}\n")
    return "".join(out)


ROBOT_YAML_BAD_INDENT = "name: broken\njoints:\n  - dh: [0, 0, 0\n    limits_deg: [-170, 170]\n"
TRUTH_UNKNOWN_EFFECT = "stiffness_Nm_per_rad: [50914, 16382, 31311, 7791.1, 5613.6, 4000]\neffects:\n  warp_drive: {w: 1}\n"
TRUTH_UNKNOWN_PARAM = "stiffness_Nm_per_rad: [50914, 16382, 31311, 7791.1, 5613.6, 4000]\neffects:\n  backlash: {zz9: 1e-4}\n"
TRUTH_OUT_OF_RANGE = "stiffness_Nm_per_rad: [50914, 16382, 31311, 7791.1, 5613.6, 4000]\neffects:\n  backlash: {b1: -1.0}\n"
TRUTH_WRONG_COUNT = "stiffness_Nm_per_rad: [50914, 16382]\n"
NOISE_NEGATIVE = "tracker_sigma_um: -10\n"
NOISE_UNKNOWN_KEY = "tracker_sigma_um: 10\ntraker_ppm: 5\n"
NOISE_NAN = "tracker_sigma_m: .nan\n"
NOISE_OUTLIER_RATE = "outlier_rate: 1.5\n"
URDF_BROKEN = "<robot name='x'><link name='a'/><joint name='j' type='revolute'><parent link='a'/>"
URDF_NO_JOINTS = "<?xml version='1.0'?><robot name='x'><link name='a'/></robot>"
URDF_BRANCHING = """<?xml version='1.0'?>
<robot name='tree'>
  <link name='base'/><link name='l1'/><link name='l2'/>
  <joint name='j1' type='revolute'><parent link='base'/><child link='l1'/><axis xyz='0 0 1'/>
    <limit lower='-1' upper='1' effort='1' velocity='1'/></joint>
  <joint name='j2' type='revolute'><parent link='base'/><child link='l2'/><axis xyz='0 0 1'/>
    <limit lower='-1' upper='1' effort='1' velocity='1'/></joint>
</robot>
"""
FIT_WRONG_FORMAT = '{"format": "not-a-fit", "version": 1}'
FIT_FUTURE_VERSION = '{"format": "stiff-fit", "version": 99}'
FIT_TRUNCATED = '{"format": "stiff-fit", "version": 1, "model": ["joint"], "parameters": [{"eff'

CASES = [
    # ------------------------------------------------------------------ command line: data files
    dict(id="cli-nan-force", kind="cli", topic="NaN",
         files={"bad.csv": HEADER6 + "1,0,0,0,0,0,0,nan,0,0,1,2,3\n" + rows(12)},
         args=["identify", "--robot", "rokae", "--data", "{tmp}/bad.csv", "-o", "{out}"],
         message="bad.csv:2:15: column 'fx_N': 'nan' is not a finite number"),
    dict(id="cli-inf-displacement", kind="cli", topic="NaN",
         files={"bad.csv": HEADER6 + rows(5) + "x,0,0,0,0,0,0,1,2,3,inf,0,0\n"},
         args=["identify", "--robot", "rokae", "--data", "{tmp}/bad.csv", "-o", "{out}"],
         message="bad.csv:7:"),
    dict(id="cli-unknown-unit", kind="cli", topic="wrong units",
         files={"bad.csv": HEADER6.replace("fx_N", "fx_lbf") + rows(12)},
         args=["identify", "--robot", "rokae", "--data", "{tmp}/bad.csv", "-o", "{out}"],
         message="unknown unit 'lbf'"),
    dict(id="cli-angle-unit-grad", kind="cli", topic="wrong units",
         files={"bad.csv": HEADER6.replace("q1_deg", "q1_grad") + rows(12)},
         args=["identify", "--robot", "rokae", "--data", "{tmp}/bad.csv", "-o", "{out}"],
         message="q1_grad"),
    dict(id="cli-displacement-in-newton", kind="cli", topic="wrong units",
         files={"bad.csv": HEADER6.replace("dx_um", "dx_N") + rows(12)},
         args=["identify", "--robot", "rokae", "--data", "{tmp}/bad.csv", "-o", "{out}"],
         message="dx_N"),
    dict(id="cli-one-measurement", kind="cli", topic="too few measurements",
         files={"few.csv": HEADER6 + rows(1)},
         args=["identify", "--robot", "rokae", "--data", "{tmp}/few.csv", "-o", "{out}"],
         message="at least 2 measurements are needed"),
    dict(id="cli-header-only", kind="cli", topic="too few measurements",
         files={"empty.csv": HEADER6},
         args=["identify", "--robot", "rokae", "--data", "{tmp}/empty.csv", "-o", "{out}"],
         message="dataset has no measurements"),
    dict(id="cli-empty-file", kind="cli", topic="bad CSV",
         files={"empty.csv": ""},
         args=["identify", "--robot", "rokae", "--data", "{tmp}/empty.csv", "-o", "{out}"],
         message="empty.csv"),
    dict(id="cli-ragged-row", kind="cli", topic="bad CSV",
         files={"bad.csv": HEADER6 + rows(3) + "r,1,2,3\n" + rows(3)},
         args=["identify", "--robot", "rokae", "--data", "{tmp}/bad.csv", "-o", "{out}"],
         message="bad.csv:5"),
    dict(id="cli-not-a-number", kind="cli", topic="bad CSV",
         files={"bad.csv": HEADER6 + rows(3) + "r,1,2,3,4,5,6,abc,0,0,1,1,1\n"},
         args=["identify", "--robot", "rokae", "--data", "{tmp}/bad.csv", "-o", "{out}"],
         message="bad.csv:5:"),
    dict(id="cli-missing-force-columns", kind="cli", topic="bad CSV",
         files={"bad.csv": "id,q1_deg,q2_deg,q3_deg,q4_deg,q5_deg,q6_deg,dx_um,dy_um,dz_um\n1,0,0,0,0,0,0,1,2,3\n"},
         args=["identify", "--robot", "rokae", "--data", "{tmp}/bad.csv", "-o", "{out}"],
         message="bad.csv:1"),
    dict(id="cli-too-many-joints", kind="cli", topic="bad CSV",
         files={"bad.csv": HEADER6.replace("q6_deg,", "q6_deg,q7_deg,") +
                "1,0,0,0,0,0,0,0,1,2,3,1,1,1\n" * 1},
         args=["identify", "--robot", "rokae", "--data", "{tmp}/bad.csv", "-o", "{out}"],
         message="q7"),
    dict(id="cli-duplicate-ids", kind="cli", topic="bad CSV",
         files={"bad.csv": HEADER6 + rows(4) + rows(1)},
         args=["identify", "--robot", "rokae", "--data", "{tmp}/bad.csv", "-o", "{out}"],
         message="m0"),
    dict(id="cli-plan-as-measurements", kind="cli", topic="bad CSV",
         args=["identify", "--robot", "rokae", "--data", "{design}", "-o", "{out}"],
         message="displacement"),
    dict(id="cli-missing-data-file", kind="cli", topic="missing files",
         args=["identify", "--robot", "rokae", "--data", "{tmp}/nope.csv", "-o", "{out}"],
         message="nope.csv: cannot open for reading"),
    dict(id="cli-data-is-a-directory", kind="cli", topic="missing files",
         args=["identify", "--robot", "rokae", "--data", "{tmp}", "-o", "{out}"],
         message="{tmp}"),
    # ------------------------------------------------------------------ command line: models, robots
    dict(id="cli-unknown-effect", kind="cli", topic="unknown effect names",
         args=["identify", "--robot", "rokae", "--data", "{data}", "--model", "joint+warp", "-o", "{out}"],
         message="unknown effect 'warp'; known effects: joint"),
    dict(id="cli-empty-model", kind="cli", topic="unknown effect names",
         args=["identify", "--robot", "rokae", "--data", "{data}", "--model", "joint++link", "-o", "{out}"],
         message="model"),
    dict(id="cli-unknown-loss", kind="cli", topic="unknown effect names",
         args=["identify", "--robot", "rokae", "--data", "{data}", "--loss", "l7", "-o", "{out}"],
         message="l7"),
    dict(id="cli-linear-with-effects", kind="cli", topic="plan requests that cannot be met",
         args=["identify", "--robot", "rokae", "--data", "{data}", "--model", "joint+link",
               "--method", "linear", "-o", "{out}"],
         message="linear method fits the model 'joint'"),
    dict(id="cli-unknown-robot", kind="cli", topic="missing files",
         args=["identify", "--robot", "kuka_kr1000", "--data", "{data}", "-o", "{out}"],
         message="no built-in robot of that name"),
    dict(id="cli-robot-yaml-syntax", kind="cli", topic="bad YAML",
         files={"robot.yaml": ROBOT_YAML_BAD_INDENT},
         args=["identify", "--robot", "{tmp}/robot.yaml", "--data", "{data}", "-o", "{out}"],
         message="robot.yaml:"),
    dict(id="cli-robot-yaml-not-a-map", kind="cli", topic="bad YAML",
         files={"robot.yaml": "- just\n- a list\n"},
         args=["identify", "--robot", "{tmp}/robot.yaml", "--data", "{data}", "-o", "{out}"],
         message="robot.yaml"),
    dict(id="cli-urdf-truncated", kind="cli", topic="bad URDF",
         files={"arm.urdf": URDF_BROKEN},
         args=["identify", "--robot", "{tmp}/arm.urdf", "--data", "{data}", "-o", "{out}"],
         message="arm.urdf"),
    dict(id="cli-urdf-no-joints", kind="cli", topic="bad URDF",
         files={"arm.urdf": URDF_NO_JOINTS},
         args=["identify", "--robot", "{tmp}/arm.urdf", "--data", "{data}", "-o", "{out}"],
         message="arm.urdf"),
    dict(id="cli-urdf-branching", kind="cli", topic="bad URDF",
         files={"tree.urdf": URDF_BRANCHING},
         args=["identify", "--robot", "{tmp}/tree.urdf", "--data", "{data}", "-o", "{out}"],
         message="tree.urdf"),
    # ------------------------------------------------------------------ command line: outputs
    dict(id="cli-output-dir-missing", kind="cli", topic="unwritable output",
         args=["identify", "--robot", "rokae", "--data", "{data}", "-o", "{tmp}/no/such/dir/fit.json"],
         message="cannot create a temporary file"),
    dict(id="cli-output-parent-is-file", kind="cli", topic="unwritable output",
         args=["identify", "--robot", "rokae", "--data", "{data}", "-o", "{data}/fit.json"],
         message="fit.json"),
    dict(id="cli-output-is-directory", kind="cli", topic="unwritable output",
         args=["simulate", "--robot", "rokae", "--stiffness", "50914,16382,31311,7791,5614,4000",
               "--count", "5", "-o", "{tmp}"],
         message="{tmp}"),
    dict(id="cli-simulate-output-dir-missing", kind="cli", topic="unwritable output",
         args=["simulate", "--robot", "rokae", "--stiffness", "50914,16382,31311,7791,5614,4000",
               "--count", "5", "-o", "{tmp}/missing/data.csv"],
         message="data.csv"),
    dict(id="cli-fmu-output-dir-missing", kind="cli", topic="unwritable output",
         args=["fmu", "export", "--robot", "rokae", "--fit", "{fit}", "-o", "{tmp}/missing/arm.fmu"],
         message="arm.fmu"),
    # ------------------------------------------------------------------ command line: simulate
    dict(id="cli-stiffness-count", kind="cli", topic="wrong sizes",
         args=["simulate", "--robot", "rokae", "--stiffness", "1,2,3", "-o", "{out}"],
         message="stiffness has 3 values, the robot has 6 joints"),
    dict(id="cli-stiffness-negative", kind="cli", topic="out of range",
         args=["simulate", "--robot", "rokae", "--stiffness=-5,1,1,1,1,1", "-o", "{out}"],
         message="stiffness[0] must be > 0"),
    dict(id="cli-stiffness-nan", kind="cli", topic="NaN",
         args=["simulate", "--robot", "rokae", "--stiffness=nan,1,1,1,1,1", "-o", "{out}"],
         message="stiffness[0] is not finite"),
    dict(id="cli-truth-unknown-effect", kind="cli", topic="unknown effect names",
         files={"truth.yaml": TRUTH_UNKNOWN_EFFECT},
         args=["simulate", "--robot", "rokae", "--truth", "{tmp}/truth.yaml", "-o", "{out}"],
         message="warp_drive"),
    dict(id="cli-truth-unknown-parameter", kind="cli", topic="bad YAML",
         files={"truth.yaml": TRUTH_UNKNOWN_PARAM},
         args=["simulate", "--robot", "rokae", "--truth", "{tmp}/truth.yaml", "-o", "{out}"],
         message="zz9"),
    dict(id="cli-truth-out-of-range", kind="cli", topic="out of range",
         files={"truth.yaml": TRUTH_OUT_OF_RANGE},
         args=["simulate", "--robot", "rokae", "--truth", "{tmp}/truth.yaml", "-o", "{out}"],
         message="truth.yaml:"),
    dict(id="cli-truth-wrong-count", kind="cli", topic="wrong sizes",
         files={"truth.yaml": TRUTH_WRONG_COUNT},
         args=["simulate", "--robot", "rokae", "--truth", "{tmp}/truth.yaml", "-o", "{out}"],
         message="truth.yaml:"),
    dict(id="cli-noise-negative-sigma", kind="cli", topic="out of range",
         files={"noise.yaml": NOISE_NEGATIVE},
         args=["simulate", "--robot", "rokae", "--count", "5", "--stiffness",
               "50914,16382,31311,7791,5614,4000", "--noise", "{tmp}/noise.yaml", "-o", "{out}"],
         message="noise.yaml:1"),
    dict(id="cli-noise-unknown-key", kind="cli", topic="bad YAML",
         files={"noise.yaml": NOISE_UNKNOWN_KEY},
         args=["simulate", "--robot", "rokae", "--count", "5", "--stiffness",
               "50914,16382,31311,7791,5614,4000", "--noise", "{tmp}/noise.yaml", "-o", "{out}"],
         message="traker_ppm"),
    dict(id="cli-noise-nan", kind="cli", topic="NaN",
         files={"noise.yaml": NOISE_NAN},
         args=["simulate", "--robot", "rokae", "--count", "5", "--stiffness",
               "50914,16382,31311,7791,5614,4000", "--noise", "{tmp}/noise.yaml", "-o", "{out}"],
         message="noise.yaml:1"),
    dict(id="cli-noise-outlier-rate", kind="cli", topic="out of range",
         files={"noise.yaml": NOISE_OUTLIER_RATE},
         args=["simulate", "--robot", "rokae", "--count", "5", "--stiffness",
               "50914,16382,31311,7791,5614,4000", "--noise", "{tmp}/noise.yaml", "-o", "{out}"],
         message="outlier_rate"),
    # ------------------------------------------------------------------ command line: fits
    dict(id="cli-fit-is-csv", kind="cli", topic="bad JSON fit",
         args=["predict", "--robot", "rokae", "--fit", "{data}", "--data", "{data}", "-o", "{out}"],
         message="not valid JSON"),
    dict(id="cli-fit-wrong-format", kind="cli", topic="bad JSON fit",
         files={"fit.json": FIT_WRONG_FORMAT},
         args=["predict", "--robot", "rokae", "--fit", "{tmp}/fit.json", "--data", "{data}", "-o", "{out}"],
         message="fit.json"),
    dict(id="cli-fit-future-version", kind="cli", topic="bad JSON fit",
         files={"fit.json": FIT_FUTURE_VERSION},
         args=["predict", "--robot", "rokae", "--fit", "{tmp}/fit.json", "--data", "{data}", "-o", "{out}"],
         message="version"),
    dict(id="cli-fit-truncated", kind="cli", topic="bad JSON fit",
         files={"fit.json": FIT_TRUNCATED},
         args=["predict", "--robot", "rokae", "--fit", "{tmp}/fit.json", "--data", "{data}", "-o", "{out}"],
         message="fit.json"),
    dict(id="cli-fit-for-other-robot", kind="cli", topic="wrong sizes",
         args=["predict", "--robot", "{tmp}/five.urdf", "--fit", "{fit}", "--data", "{data}", "-o", "{out}"],
         files={"five.urdf": "@FIVE_JOINT_URDF@"},
         message="joint"),
    dict(id="cli-fmu-missing-fit", kind="cli", topic="missing files",
         args=["fmu", "export", "--robot", "rokae", "--fit", "{tmp}/nofit.json", "-o", "{out}"],
         message="nofit.json"),
    dict(id="cli-fmu-version-4", kind="cli", topic="out of range", one_line=False,
         args=["fmu", "export", "--robot", "rokae", "--fit", "{fit}", "--fmi", "4", "-o", "{out}"],
         message="invalid choice: 4"),
    # ------------------------------------------------------------------ command line: plans
    dict(id="cli-plan-empty-load-range", kind="cli", topic="plan requests that cannot be met",
         args=["plan", "--robot", "rokae", "--count", "10", "--load-range", "50,10", "-o", "{out}"],
         message="empty load range [50, 10] N"),
    dict(id="cli-plan-unknown-criterion", kind="cli", topic="plan requests that cannot be met",
         args=["plan", "--robot", "rokae", "--criterion", "max_fun", "-o", "{out}"],
         message="unknown plan criterion 'max_fun'"),
    dict(id="cli-plan-zero-count", kind="cli", topic="plan requests that cannot be met",
         args=["plan", "--robot", "rokae", "--count", "0", "-o", "{out}"],
         message="count"),
    dict(id="cli-plan-fix-unknown-joint", kind="cli", topic="plan requests that cannot be met",
         args=["plan", "--robot", "rokae", "--fix", "9=0", "-o", "{out}"],
         message="9"),
    dict(id="cli-plan-impossible-min-sigma", kind="cli", topic="singular poses",
         args=["plan", "--robot", "rokae", "--count", "10", "--min-sigma", "50", "--pool-poses", "50",
               "-o", "{out}"],
         message="sigma"),
    dict(id="cli-plan-range-zero", kind="cli", topic="degenerate plans",
         args=["plan", "--robot", "rokae", "--count", "10", "--range", "0", "-o", "{out}"],
         message="range"),
    # ------------------------------------------------------------------ C ABI (ctypes)
    dict(id="capi-dataset-zero-rows", kind="capi", topic="too few measurements",
         code="lib.stiff_dataset_create(out(), 0, 6, dbl([0]*6), dbl([0]*3), None, None, None)",
         status=-1, message="rows must be > 0"),
    dict(id="capi-dataset-dof-65", kind="capi", topic="wrong sizes",
         code="lib.stiff_dataset_create(out(), 1, 65, dbl([0]*65), dbl([0]*3), None, None, None)",
         status=-1, message="dof must be in 1..64"),
    dict(id="capi-dataset-nan-q", kind="capi", topic="NaN",
         code="lib.stiff_dataset_create(out(), 1, 6, dbl([0, 0, 0, NAN, 0, 0]), dbl([0]*3), None, None, None)",
         status=-1, message="q[3] is not finite"),
    dict(id="capi-dataset-inf-force", kind="capi", topic="NaN",
         code="lib.stiff_dataset_create(out(), 1, 6, dbl([0]*6), dbl([1, INF, 0]), None, None, None)",
         status=-1, message="force[1] is not finite"),
    dict(id="capi-dataset-zero-sigma", kind="capi", topic="out of range",
         code="lib.stiff_dataset_create(out(), 2, 6, dbl([0]*12), dbl([0]*6), None, dbl([0]*6), dbl([1e-5, 0]))",
         status=-1, message="sigma_d[1] must be > 0"),
    dict(id="capi-dataset-null-q", kind="capi", topic="wrong sizes",
         code="lib.stiff_dataset_create(out(), 1, 6, None, dbl([0]*3), None, None, None)",
         status=-1, message="q is NULL"),
    dict(id="capi-identify-no-displacement", kind="capi", topic="bad CSV",
         code="lib.stiff_identify(out(), robot(), dataset(displacement=False), None)",
         status=-1, message="displacement"),
    dict(id="capi-identify-unknown-loss", kind="capi", topic="unknown effect names",
         code="lib.stiff_identify(out(), robot(), dataset(), options(loss=b'l7'))",
         status=-1, message="l7"),
    dict(id="capi-identify-unknown-effect", kind="capi", topic="unknown effect names",
         code="lib.stiff_identify(out(), robot(), dataset(), options(model=b'joint+warp'))",
         status=-1, message="unknown effect 'warp'"),
    dict(id="capi-identify-bad-method", kind="capi", topic="out of range",
         code="lib.stiff_identify(out(), robot(), dataset(), options(method=7))",
         status=-1, message="unknown method 7"),
    dict(id="capi-identify-nan-loss-scale", kind="capi", topic="NaN",
         code="lib.stiff_identify(out(), robot(), dataset(), options(loss=b'huber', loss_scale_m=NAN))",
         status=-1, message="loss_scale_m must be finite"),
    dict(id="capi-identify-zero-loads", kind="capi", topic="degenerate measurements",
         code="lib.stiff_identify(out(), robot(), dataset(zero_force=True), None)",
         status=-6, message="every observation column is zero (no load?)"),
    dict(id="capi-identify-zero-loads-ceres", kind="capi", topic="effects the data cannot identify",
         code="lib.stiff_identify(out(), robot(), dataset(zero_force=True), options(model=b'joint+link'))",
         status=-6, message="no parameter of model 'joint+link' is identifiable"),
    dict(id="capi-identify-one-row", kind="capi", topic="too few measurements",
         code="lib.stiff_identify(out(), robot(), dataset(rows=1), None)",
         status=-1, message="at least 2 measurements are needed"),
    dict(id="capi-predict-wrong-dof", kind="capi", topic="wrong sizes",
         code="lib.stiff_predict_batch(dbl([0]*6), 6, None, model(), dbl([0]*5), dbl([0]*6), 1, 5)",
         status=-1, message="q has 5 values, the robot has 6 joints"),
    dict(id="capi-predict-nan-wrench", kind="capi", topic="NaN",
         code="lib.stiff_predict_batch(dbl([0]*12), 12, None, model(), dbl([0.1]*12), dbl([0]*6 + [0, NAN, 0, 0, 0, 0]), 2, 6)",
         status=-1, message="row 1: wrench[1] is not finite"),
    dict(id="capi-predict-small-buffer", kind="capi", topic="wrong sizes",
         code="lib.stiff_predict_batch(dbl([0]*6), 6, None, model(), dbl([0.1]*12), dbl([1]*12), 2, 6)",
         status=-5, message="buffer holds 6 values, 12 needed"),
    dict(id="capi-fit-missing", kind="capi", topic="missing files",
         code="lib.stiff_result_read_json(out(), b'{tmp}/none.json')",
         status=-4, message="none.json"),
    dict(id="capi-write-fit-missing-dir", kind="capi", topic="unwritable output",
         code="lib.stiff_result_write_json(fit(), b'{tmp}/no/such/fit.json')",
         status=-4, message="cannot create a temporary file"),
    dict(id="capi-write-csv-parent-is-file", kind="capi", topic="unwritable output",
         code="lib.stiff_dataset_write_csv(dataset(), b'{data}/out.csv')",
         status=-4, message="out.csv"),
    dict(id="capi-robot-branching-urdf", kind="capi", topic="bad URDF",
         files={"tree.urdf": URDF_BRANCHING},
         code="lib.stiff_robot_load(out(), b'{tmp}/tree.urdf')",
         status=-3, message="tree.urdf"),
    dict(id="capi-options-future-struct", kind="capi", topic="wrong sizes",
         code="lib.stiff_identify(out(), robot(), dataset(), options(struct_size_extra=8, poison=True))",
         status=-1, message="struct_size is larger"),
    # ------------------------------------------------------------------ Python package
    dict(id="py-robot-missing", kind="python", topic="missing files",
         code="stiff.Robot('{tmp}/none.yaml')", error="StiffIOError", status=-4,
         message="none.yaml: cannot open"),
    dict(id="py-dataset-nan", kind="python", topic="NaN",
         files={"bad.csv": HEADER6 + "1,0,0,0,0,0,0,0,nan,0,1,2,3\n"},
         code="stiff.Dataset.read('{tmp}/bad.csv')", error="ParseError", status=-3,
         message="bad.csv:2:"),
    dict(id="py-from-arrays-shapes", kind="python", topic="wrong sizes",
         code="stiff.Dataset.from_arrays(np.zeros((4, 6)), np.zeros((3, 3)))", error="ValueError",
         message=""),
    dict(id="py-identify-unknown-effect", kind="python", topic="unknown effect names",
         code="stiff.identify(stiff.Robot('{robot}'), stiff.Dataset.read('{data}'), model='joint+warp')",
         error="InvalidArgumentError", status=-1, message="unknown effect 'warp'"),
    dict(id="py-predict-wrong-q", kind="python", topic="wrong sizes",
         code="stiff.Model(stiff.Robot('{robot}'), stiff.Fit.read('{fit}')).predict([0.1] * 5, [1] * 6)",
         error="ValueError", message="5"),
    dict(id="py-fit-bad-json", kind="python", topic="bad JSON fit",
         files={"fit.json": FIT_TRUNCATED},
         code="stiff.Fit.read('{tmp}/fit.json')", error="ParseError", status=-3, message="fit.json"),
    dict(id="py-simulate-wrong-count", kind="python", topic="wrong sizes",
         code="stiff.simulate(stiff.Robot('{robot}'), stiffness=[1e4] * 5)",
         error="InvalidArgumentError", status=-1, message="stiffness has 5 values"),
    dict(id="py-describe-unknown-effect", kind="python", topic="unknown effect names",
         code="stiff.describe_effect('warp')", error="InvalidArgumentError", status=-1,
         message="warp"),
    # ------------------------------------------------------------------ FMU (fmpy)
    dict(id="fmu2-negative-compliance", kind="fmu", topic="FMU bad parameters",
         code="fmu_set('{fmu2}', joint_c2=-1e-5)", message="joint_c2"),
    dict(id="fmu2-nan-compliance", kind="fmu", topic="FMU bad parameters",
         code="fmu_set('{fmu2}', joint_c1=NAN)", message="joint_c1"),
    dict(id="fmu3-inf-compliance", kind="fmu", topic="FMU bad parameters",
         code="fmu_set('{fmu3}', joint_c3=INF)", message="joint_c3"),
    dict(id="fmu2-nan-input", kind="fmu", topic="NaN",
         code="fmu_set('{fmu2}', started=True, q1=NAN)", message="q1"),
    dict(id="fmu2-bad-wrench-frame", kind="fmu", topic="FMU bad parameters",
         code="fmu_set_int('{fmu2}', wrench_frame=7)", message="wrench_frame"),
    dict(id="fmu3-bad-wrench-frame", kind="fmu", topic="FMU bad parameters",
         code="fmu_set_int('{fmu3}', wrench_frame=-1)", message="wrench_frame"),
    dict(id="fmu2-wrong-guid", kind="fmu", topic="FMU bad parameters",
         code="fmu_instantiate('{fmu2}', guid='{{00000000-0000-0000-0000-000000000000}}')",
         message="does not match"),
    dict(id="fmu2-missing-model-file", kind="fmu", topic="missing files",
         code="fmu_instantiate('{fmu2}', edit='delete-model')", message="model"),
]


def markdown_table() -> str:
    """The catalogue as a Markdown table (docs/reliability.md)."""
    lines = ["| # | case | interface | bad input | expected |", "| ---: | --- | --- | --- | --- |"]
    for i, c in enumerate(CASES, 1):
        if c["kind"] == "cli":
            what = "`stiff " + " ".join(a for a in c["args"][:2] if not a.startswith("-")) + "`"
            exp = f"exit {c.get('exit', 2)}"
        elif c["kind"] == "capi":
            what = "`" + c["code"].split("(")[0].replace("lib.", "") + "`"
            exp = f"status {c['status']}"
        elif c["kind"] == "python":
            what = "`" + c["code"].split("(")[0] + "`"
            exp = c["error"]
        else:
            what = "FMU"
            exp = "FMI error + log"
        msg = c["message"].replace("|", "\\|").replace("{tmp}", "<dir>") or "(any)"
        lines.append(f"| {i} | {c['id']} | {what} | {c['topic']} | {exp}: \"{msg}\" |")
    return "\n".join(lines)


if __name__ == "__main__":
    print(markdown_table())
