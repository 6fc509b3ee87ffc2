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


