import os
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[3]


@pytest.fixture(scope="session")
def root() -> Path:
    return ROOT


@pytest.fixture(scope="session")
def build_dir() -> Path:
    return Path(os.environ.get("STIFF_BUILD_DIR", ROOT / "build"))


@pytest.fixture(scope="session")
def rokae_path(root) -> str:
    return str(root / "examples" / "robots" / "rokae.yaml")


@pytest.fixture(scope="session")
def design_a(root) -> str:
    return str(root / "examples" / "paper" / "design_kappa_a.csv")


PAPER_K = [5.0914e4, 1.6382e4, 3.1311e4, 7.7911e3, 5.6136e3, 4.0e3]
