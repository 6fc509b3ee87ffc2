"""Fixtures of the FMU tests (helpers and the numpy reference are in fmu_reference.py)."""

import pathlib
import sys

import pytest

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
from fmu_reference import Exporter  # noqa: E402


@pytest.fixture(scope="session")
def exporter(tmp_path_factory):
    return Exporter(tmp_path_factory.mktemp("fmus"))


@pytest.fixture(scope="session")
def fmu2(exporter):
    return exporter.export("arm2", 2)


@pytest.fixture(scope="session")
def fmu3(exporter):
    return exporter.export("arm3", 3)
