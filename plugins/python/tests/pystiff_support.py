"""Constants shared by the Python tests (a uniquely named module: several test folders have a
conftest.py)."""

# The paper's identified stiffness (Jiang & Fang 2023) [N*m/rad]; joint 6 assumed (not identified).
PAPER_K = [5.0914e4, 1.6382e4, 3.1311e4, 7.7911e3, 5.6136e3, 4.0e3]
