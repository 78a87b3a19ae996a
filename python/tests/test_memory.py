"""An array too large for the memory left raises MemoryError, as SciPy's
transform does, instead of aborting the interpreter."""

import subprocess
import sys
import textwrap

import pytest

CHILD = textwrap.dedent("""
    import resource

    import numpy as np

    import edtmap

    def vm_size():
        with open("/proc/self/status") as f:
            return next(int(l.split()[1]) * 1024 for l in f if l.startswith("VmSize:"))

    grid = np.ones((400, 400, 400), dtype=np.uint8)
    grid[0, 0, 0] = 0
    small = np.ascontiguousarray(grid[:9, :9, :9])
    want = edtmap.edt(small)  # starts the threads before the limit
    # 128 MiB more address space: less than any output of the grid.
    soft = vm_size() + (128 << 20)
    resource.setrlimit(resource.RLIMIT_AS, (soft, resource.getrlimit(resource.RLIMIT_AS)[1]))
    calls = {
        "edt": lambda: edtmap.edt(grid),
        "edtsq": lambda: edtmap.edtsq(grid, anisotropy=(1.0, 2.0, 0.5)),
        "distance_transform_edt": lambda: edtmap.distance_transform_edt(grid),
        "distance_transform_edt indices": lambda: edtmap.distance_transform_edt(grid, return_indices=True),
        "obstacle_distance": lambda: edtmap.obstacle_distance(grid),
        "obstacle_distance nearest": lambda: edtmap.obstacle_distance(grid, return_nearest=True),
    }
    for name, call in calls.items():
        try:
            call()
        except MemoryError as e:
            assert "(400, 400, 400)" in str(e) and "bytes" in str(e), e
            print(name, "->", e)
        else:
            raise SystemExit(f"{name}: no MemoryError")
    # Nothing was left half done.
    assert np.array_equal(edtmap.edt(small), want)
""")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc/self/status")
def test_too_large_raises_memory_error():
    done = subprocess.run([sys.executable, "-c", CHILD], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, f"exit {done.returncode}\n{done.stdout}\n{done.stderr}"
    assert done.stdout.count("->") == 6, done.stdout
