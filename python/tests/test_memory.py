"""An array too large for the memory left raises MemoryError, as SciPy's
transform does, instead of aborting the interpreter."""

import os
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


# The children count address space to the megabyte: one malloc arena for
# every thread, or a thread that first allocates after the limit maps a
# fresh 64 MiB arena and takes the room the test leaves for its output.
CHILD_ENV = dict(os.environ, MALLOC_ARENA_MAX="1")


# Room for the outputs but not for the core's nearest-obstacle field: the
# distance-only transform answers, exactly as the peers.
LEAN_CHILD = textwrap.dedent("""
    import resource

    import edt
    import numpy as np
    from scipy import ndimage

    import edtmap

    def vm_size():
        with open("/proc/self/status") as f:
            return next(int(l.split()[1]) * 1024 for l in f if l.startswith("VmSize:"))

    n = 200
    grid = np.ones((n, n, n), dtype=np.uint8)
    rng = np.random.default_rng(5)
    grid.reshape(-1)[rng.integers(0, grid.size, size=grid.size // 200)] = 0
    want_dte = ndimage.distance_transform_edt(grid)
    want_edt = edt.edt(grid)
    want_obstacles = ndimage.distance_transform_edt(grid).astype(np.float32)
    # Without any zero, SciPy measures to a virtual zero before the first row.
    ones = np.ones_like(grid)
    want_ones = ndimage.distance_transform_edt(ones, sampling=(2, 1, 3))
    edtmap.edt(np.ascontiguousarray(grid[:9, :9, :9]))  # starts the threads before the limit
    # The float64 output (64 MB, which may come from freed heap or a fresh
    # mapping) and the lean transform's room fit; the field besides them
    # (64 MB more) does not whenever the output took fresh address space.
    soft = vm_size() + (160 << 20)
    resource.setrlimit(resource.RLIMIT_AS, (soft, resource.getrlimit(resource.RLIMIT_AS)[1]))
    assert np.array_equal(edtmap.distance_transform_edt(grid), want_dte)
    assert np.array_equal(edtmap.edt(grid), want_edt)
    assert np.array_equal(edtmap.obstacle_distance(grid == 0), want_obstacles)
    assert np.array_equal(edtmap.distance_transform_edt(ones, sampling=(2, 1, 3)), want_ones)
    print("equal")
""")


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc/self/status")
def test_without_room_for_the_field_the_results_are_the_same(tmp_path):
    # From a folder of its own: `python -c` puts the working folder first on
    # sys.path, and from python/ that is the source tree, not the package.
    done = subprocess.run([sys.executable, "-c", LEAN_CHILD], capture_output=True, text=True, timeout=300, cwd=tmp_path, env=CHILD_ENV)
    assert done.returncode == 0 and "equal" in done.stdout, f"exit {done.returncode}\n{done.stdout}\n{done.stderr}"


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc/self/status")
def test_too_large_raises_memory_error(tmp_path):
    done = subprocess.run([sys.executable, "-c", CHILD], capture_output=True, text=True, timeout=300, cwd=tmp_path, env=CHILD_ENV)
    assert done.returncode == 0, f"exit {done.returncode}\n{done.stdout}\n{done.stderr}"
    assert done.stdout.count("->") == 6, done.stdout
