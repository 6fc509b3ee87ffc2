"""Constants shared by the Python tests (a uniquely named module: several test folders have a
conftest.py)."""

# The paper's identified stiffness (Jiang & Fang 2023) [N*m/rad]; joint 6 assumed (not identified).
PAPER_K = [5.0914e4, 1.6382e4, 3.1311e4, 7.7911e3, 5.6136e3, 4.0e3]


def bench_module(root, name):
    """A script of bench/ imported as a module (its own imports of bench/ resolved)."""
    import importlib.util
    import sys

    spec = importlib.util.spec_from_file_location(name, root / "bench" / f"{name}.py")
    sys.path.insert(0, str(root / "bench"))
    try:
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
    finally:
        sys.path.remove(str(root / "bench"))
    return module
