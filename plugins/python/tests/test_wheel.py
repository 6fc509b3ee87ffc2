"""`pip wheel plugins/python` builds a wheel that bundles libstiff_c (and the built-in data) and
installs into a fresh virtual environment, where the package and the command line work."""
import os
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import numpy
import pytest

import stiff


def test_wheel_bundles_the_library_and_works_in_a_fresh_venv(tmp_path, root):
    pkg = Path(stiff.__file__).resolve().parent
    if not (root / "plugins" / "python" / "stiff" / "_lib" / "libstiff_c.so").exists():
        pytest.skip("the C library is not staged into plugins/python (run make build)")
    wheels = tmp_path / "wheels"
    subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "--no-build-isolation",
                    "-w", str(wheels), str(root / "plugins" / "python")], check=True)
    (wheel,) = wheels.glob("stiff-*.whl")
    names = zipfile.ZipFile(wheel).namelist()
    assert "stiff/_lib/libstiff_c.so" in names
    assert "stiff/_data/robots/rokae.yaml" in names
    assert not wheel.name.endswith("-none-any.whl")  # a platform wheel: it carries a binary

    venv = tmp_path / "fresh"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True)
    py = venv / "bin" / "python"
    site = subprocess.run([str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                          check=True, capture_output=True, text=True).stdout.strip()
    # numpy from this environment (no network in tests); the wheel itself with --no-deps.
    # Link numpy (and its bundled libraries) only: a .pth to the whole site-packages would
    # make the already installed stiff visible too.
    np_dir = Path(numpy.__file__).resolve().parent
    for d in [np_dir, *np_dir.parent.glob("numpy.libs")]:
        os.symlink(d, Path(site, d.name))
    subprocess.run([sys.executable, "-m", "pip", "--python", str(py), "install", "-q", "--no-deps",
                    str(wheel)], check=True)
    env = {k: v for k, v in os.environ.items() if k not in ("STIFF_LIBRARY", "STIFF_BUILD_DIR", "PYTHONPATH")}
    code = ("import stiff, numpy as np; from stiff import _capi; "
            "assert 'fresh' in str(_capi.LIBRARY_PATH), _capi.LIBRARY_PATH; "
            "from stiff.cli.common import robot_path; r = stiff.Robot(robot_path('rokae')); "
            "d = stiff.simulate(r, stiff.random_design(r, 20), stiffness=[5e4, 1.6e4, 3e4, 8e3, 5e3, 4e3], tracker_sigma_m=0); "
            "f = stiff.identify(r, d); print(np.round(f.stiffness[:5]))")
    run = subprocess.run([str(py), "-c", code], capture_output=True, text=True, env=env)
    assert run.returncode == 0, run.stderr
    out = run.stdout
    assert "50000" in out.replace(".", "").replace(" ", "") or "5e+04" in out
    ver = subprocess.run([str(venv / "bin" / "stiff"), "--version"], check=True, capture_output=True,
                         text=True, env=env).stdout
    assert ver.startswith("stiff ")
