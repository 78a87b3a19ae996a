"""edtmap's distance transforms against SciPy, the ``edt`` package and a
brute-force oracle, on seeded random grids."""

import numpy as np
import pytest
import scipy.ndimage as ndi

import edt as edt_package
import edtmap

SHAPES = [(1,), (13,), (1, 1), (17, 23), (1, 31), (29, 1), (9, 11, 7), (1, 12, 10), (14, 1, 9),
          (8, 10, 1), (3, 2, 40)]
DTYPES = [bool, np.uint8, np.int8, np.int16, np.uint16, np.int32, np.uint32, np.int64, np.uint64]


def random_mask(shape, zeros, seed):
    """Nonzero elements with a fraction ``zeros`` of zeros."""
    return np.random.default_rng(seed).random(shape) >= zeros


def brute_force(mask, sampling):
    """Squared distance of every element to the nearest zero of ``mask``."""
    zeros = np.argwhere(~mask)
    coords = np.indices(mask.shape).reshape(mask.ndim, -1).T
    w = np.asarray(sampling, dtype=np.float64)
    d = (((coords[:, None, :] - zeros[None, :, :]) * w) ** 2).sum(axis=2)
    return d.min(axis=1).reshape(mask.shape)


@pytest.mark.parametrize("shape", SHAPES)
@pytest.mark.parametrize("zeros", [0.0, 0.02, 0.3, 1.0])
def test_equals_scipy_exactly(shape, zeros):
    for seed in range(3):
        mask = random_mask(shape, zeros, seed)
        d, ind = edtmap.distance_transform_edt(mask, return_indices=True)
        want_d, want_ind = ndi.distance_transform_edt(mask, return_indices=True)
        assert d.dtype == np.float64 and d.shape == mask.shape
        assert ind.dtype == np.int32 and ind.shape == (mask.ndim,) + mask.shape
        np.testing.assert_array_equal(d, want_d)
        if (~mask).any():
            # Ties may pick another zero: each index must be a zero element
            # at exactly the distance.
            assert not mask[tuple(ind)].any()
            offsets = ind - np.indices(mask.shape)
            np.testing.assert_array_equal(np.sqrt((offsets.astype(np.float64) ** 2).sum(axis=0)), d)
        else:
            # SciPy's convention without any zero: index -1 of axis 0.
            np.testing.assert_array_equal(ind, want_ind)


@pytest.mark.parametrize("dtype", DTYPES)
@pytest.mark.parametrize("order", ["C", "F"])
def test_dtypes_and_orders(dtype, order):
    values = np.random.default_rng(5).integers(0, 3, size=(12, 9, 14)) * (
        np.random.default_rng(6).random((12, 9, 14)) > 0.1)
    grid = np.array(values.astype(dtype), order=order)
    d, ind = edtmap.distance_transform_edt(grid, return_indices=True)
    want_d, _ = ndi.distance_transform_edt(grid, return_indices=True)
    np.testing.assert_array_equal(d, want_d)
    assert not grid[tuple(ind)].any()
    for s in [(2.0, 1.0, 3.0), (0.3, 0.7, 0.05)]:
        np.testing.assert_allclose(edtmap.distance_transform_edt(grid, sampling=s),
                                   ndi.distance_transform_edt(grid, sampling=s), rtol=1e-14)


def test_strided_views_and_floats():
    base = random_mask((30, 40, 20), 0.05, 9)
    view = base[::2, 3:, ::-1]
    np.testing.assert_array_equal(edtmap.distance_transform_edt(view), ndi.distance_transform_edt(view))
    floats = base.astype(np.float32) * np.float32(-0.5)
    np.testing.assert_array_equal(edtmap.distance_transform_edt(floats), ndi.distance_transform_edt(floats))


@pytest.mark.parametrize("shape", [(23, 17), (11, 9, 13), (1, 15, 8), (40,)])
def test_sampling_matches_brute_force_and_scipy(shape):
    rng = np.random.default_rng(len(shape))
    for sampling in [(3, 1, 2), (0.1, 0.25, 1.7), (1e-3, 5.0, 0.4), (2, 2, 2)]:
        s = sampling[: len(shape)]
        mask = random_mask(shape, 0.05, int(rng.integers(1 << 30)))
        mask.flat[0] = False
        d, ind = edtmap.distance_transform_edt(mask, sampling=s, return_indices=True)
        want = np.sqrt(brute_force(mask, s))
        np.testing.assert_allclose(d, want, rtol=1e-14, atol=0)
        np.testing.assert_allclose(d, ndi.distance_transform_edt(mask, sampling=s), rtol=1e-14)
        assert not mask[tuple(ind)].any()
        offsets = (ind - np.indices(mask.shape)) * np.reshape(s, (-1,) + (1,) * mask.ndim)
        np.testing.assert_allclose(np.sqrt((offsets ** 2).sum(axis=0)), want, rtol=1e-14)


def test_integer_sampling_is_exact():
    mask = random_mask((20, 30, 16), 0.03, 4)
    s = (3, 1, 7)
    np.testing.assert_array_equal(edtmap.distance_transform_edt(mask, sampling=s),
                                  ndi.distance_transform_edt(mask, sampling=s))


def test_scipy_return_forms():
    mask = random_mask((10, 12), 0.1, 2)
    ind = edtmap.distance_transform_edt(mask, return_distances=False, return_indices=True)
    assert ind.shape == (2, 10, 12)
    out_d = np.empty(mask.shape)
    out_i = np.empty((2,) + mask.shape, dtype=np.int32)
    assert edtmap.distance_transform_edt(mask, distances=out_d, indices=out_i) is None
    np.testing.assert_array_equal(out_d, ndi.distance_transform_edt(mask))
    with pytest.raises(RuntimeError):
        edtmap.distance_transform_edt(mask, return_distances=False)


@pytest.mark.parametrize("shape", [(17, 23), (9, 11, 7), (1, 12, 10), (40, 1, 3)])
@pytest.mark.parametrize("order", ["C", "F"])
def test_edt_equals_edt_package(shape, order):
    for seed, zeros in enumerate([0.0, 0.01, 0.2, 1.0]):
        mask = np.array(random_mask(shape, zeros, seed), dtype=np.uint8, order=order)
        for border in [False, True]:
            got = edtmap.edt(mask, black_border=border)
            assert got.dtype == np.float32 and got.shape == mask.shape
            np.testing.assert_array_equal(got, edt_package.edt(mask, black_border=border))
            np.testing.assert_array_equal(edtmap.edtsq(mask, black_border=border),
                                          edt_package.edtsq(mask, black_border=border))
        a = (2.0, 0.5, 3.0)[: len(shape)]
        np.testing.assert_allclose(edtmap.edt(mask, anisotropy=a), edt_package.edt(mask, anisotropy=a),
                                   rtol=2e-7)


def test_edt_multilabel_equals_edt_package():
    rng = np.random.default_rng(3)
    for shape in [(20, 30, 10), (31, 17)]:
        labels = rng.integers(0, 4, size=shape).astype(np.uint32)
        blocks = np.kron(rng.integers(0, 5, size=(6, 6)), np.ones((5, 5), dtype=np.int64))
        for data in [labels, blocks]:
            for border in [False, True]:
                np.testing.assert_array_equal(edtmap.edt(data, black_border=border),
                                              edt_package.edt(data, black_border=border))
            a = (1.0, 2.0, 3.0)[: data.ndim]
            np.testing.assert_allclose(edtmap.edt(data, anisotropy=a), edt_package.edt(data, anisotropy=a),
                                       rtol=2e-7)


def random_labels(shape, count, seed):
    """Labels 1..count in patches (runs along every axis) with some
    background and scattered single voxels, seeded."""
    rng = np.random.default_rng(seed)
    coarse = rng.integers(0, count + 1, size=tuple(max(n // 3, 1) for n in shape))
    patches = coarse[np.ix_(*[np.minimum(np.arange(n) // 3, c - 1) for n, c in zip(shape, coarse.shape)])]
    scattered = rng.integers(0, count + 1, size=shape)
    return np.where(rng.random(shape) < 0.15, scattered, patches)


def label_oracle(labels, black_border, sampling):
    """Brute force: each labelled voxel's distance to the nearest voxel of
    another label (or the outside, with black_border)."""
    out = np.zeros(labels.shape)
    for value in np.unique(labels[labels != 0]):
        inside = labels == value
        if black_border:
            padded = np.pad(inside, 1)
            d = np.sqrt(brute_force(padded, sampling))[tuple(slice(1, -1) for _ in labels.shape)]
        elif inside.all():
            d = np.full(labels.shape, np.inf)
        else:
            d = np.sqrt(brute_force(inside, sampling))
        out[inside] = d[inside]
    return out


LABEL_SHAPES = [(1,), (40,), (1, 1), (23, 17), (1, 9), (9, 1), (12, 9, 14), (5, 1, 7), (1, 1, 6), (20, 3, 1)]


@pytest.mark.parametrize("shape", LABEL_SHAPES)
@pytest.mark.parametrize("count", [1, 3, 40])
def test_edt_random_labels_equal_edt_package(shape, count):
    for seed in range(3):
        labels = random_labels(shape, count, seed + 100 * count)
        for dtype in [np.uint8, np.int16, np.uint32, np.int64]:
            data = labels.astype(dtype)
            for border in [False, True]:
                np.testing.assert_array_equal(edtmap.edt(data, black_border=border),
                                              edt_package.edt(data, black_border=border))
                np.testing.assert_array_equal(edtmap.edtsq(data, black_border=border),
                                              edt_package.edtsq(data, black_border=border))
        for a in [(2.0, 1.0, 3.0), (3.0, 3.0, 3.0), (0.3, 1.7, 0.45)]:
            a = a[: len(shape)]
            for border in [False, True]:
                got = edtmap.edt(labels, anisotropy=a, black_border=border)
                theirs = edt_package.edt(labels, anisotropy=a[0] if len(a) == 1 else a, black_border=border)
                if all(float(w).is_integer() for w in a):
                    np.testing.assert_array_equal(got, theirs)
                else:
                    # edt rounds to float32 at every step of its arithmetic,
                    # edtmap after each pass: a few float32 ulps apart.
                    np.testing.assert_allclose(got, theirs, rtol=6e-7)
                np.testing.assert_allclose(got, label_oracle(labels, border, a), rtol=3e-7)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_edt_float_labels_equal_edt_package(dtype):
    rng = np.random.default_rng(21)
    values = np.array([0.0, -0.0, 0.5, -2.25, 1e-30, 3.0, 1e10], dtype=dtype)
    for shape in [(50,), (19, 23), (9, 12, 10)]:
        data = values[random_labels(shape, len(values) - 1, int(rng.integers(1 << 30)))]
        assert len(np.unique(data[data != 0])) > 2
        for border in [False, True]:
            got = edtmap.edt(data, black_border=border)
            np.testing.assert_array_equal(got, edt_package.edt(data, black_border=border))
            # Each distinct value is a label: not the same as nonzero.
            if border:
                assert not np.array_equal(got, edt_package.edt(data != 0, black_border=border))
            np.testing.assert_array_equal(edtmap.edtsq(data, black_border=border),
                                          edt_package.edtsq(data, black_border=border))


def test_edt_threads():
    mask = random_mask((30, 20, 25), 0.02, 8)
    want = edt_package.edt(mask)
    for parallel in [0, 1, 2, 3]:
        np.testing.assert_array_equal(edtmap.edt(mask, parallel=parallel), want)


@pytest.mark.parametrize("order", ["C", "F"])
def test_obstacle_distance(order):
    obstacles = np.zeros((12, 15, 9), dtype=bool, order=order)
    obstacles[3, 4, 5] = obstacles[10, 1, 2] = True
    d, near = edtmap.obstacle_distance(obstacles, voxel_size=(0.1, 0.2, 0.05), return_nearest=True)
    assert d.dtype == np.float32 and near.shape == obstacles.shape + (3,)
    np.testing.assert_allclose(d, np.sqrt(brute_force(~obstacles, (0.1, 0.2, 0.05))), rtol=1e-7)
    assert obstacles[tuple(np.moveaxis(near, -1, 0))].all()
    np.testing.assert_array_equal(edtmap.obstacle_distance(obstacles),
                                  ndi.distance_transform_edt(~obstacles).astype(np.float32))
    d, near = edtmap.obstacle_distance(np.zeros((4, 5)), return_nearest=True)
    assert np.isinf(d).all() and (near == -1).all()


@pytest.mark.parametrize("call", [
    lambda a: edtmap.distance_transform_edt(a),
    lambda a: edtmap.edt(a),
    lambda a: edtmap.obstacle_distance(a),
])
def test_bad_inputs(call):
    with pytest.raises(ValueError, match="input|data|obstacles.*dimensions"):
        call(np.ones((2, 2, 2, 2)))
    with pytest.raises(TypeError, match="complex"):
        call(np.ones((3, 3), dtype=complex))
    with pytest.raises(TypeError):
        call(np.array([["a", "b"]]))


EMPTY_AND_SCALARS = [np.ones(()), np.zeros(()), np.array(7, dtype=np.int16), np.ones((0,)),
                     np.zeros((0, 3), dtype=np.uint8), np.ones((3, 0, 2), dtype=bool)]


@pytest.mark.parametrize("a", EMPTY_AND_SCALARS, ids=lambda a: f"{a.dtype}{a.shape}")
def test_empty_and_0d_as_scipy(a):
    for kwargs in [{}, {"sampling": 2.0}]:
        got = edtmap.distance_transform_edt(a, **kwargs)
        want = ndi.distance_transform_edt(a, **kwargs)
        assert got.shape == want.shape and got.dtype == want.dtype
        np.testing.assert_array_equal(got, want)
    got_d, got_i = edtmap.distance_transform_edt(a, return_indices=True)
    want_d, want_i = ndi.distance_transform_edt(a, return_indices=True)
    assert got_i.shape == want_i.shape and got_i.dtype == want_i.dtype
    np.testing.assert_array_equal(got_d, want_d)
    np.testing.assert_array_equal(got_i, want_i)


@pytest.mark.parametrize("a", EMPTY_AND_SCALARS, ids=lambda a: f"{a.dtype}{a.shape}")
def test_empty_and_0d_as_edt_package(a):
    for ours, theirs in [(edtmap.edt, edt_package.edt), (edtmap.edtsq, edt_package.edtsq)]:
        try:
            want = theirs(a)
        except TypeError:
            # The edt package refuses 0-d input; so does edtmap, naming it.
            with pytest.raises(ValueError, match="data must have 1, 2 or 3 dimensions, not 0"):
                ours(a)
            continue
        got = ours(a)
        assert got.shape == want.shape and got.dtype == want.dtype


def test_empty_obstacle_distance():
    d, near = edtmap.obstacle_distance(np.zeros((0, 4), dtype=bool), return_nearest=True)
    assert d.shape == (0, 4) and d.dtype == np.float32
    assert near.shape == (0, 4, 2) and near.dtype == np.int32
    with pytest.raises(ValueError, match="obstacles must have 1, 2 or 3 dimensions, not 0"):
        edtmap.obstacle_distance(np.ones(()))


def test_bad_spacings():
    mask = np.ones((4, 5), dtype=bool)
    for bad in [(1.0,), (1.0, 0.0), (1.0, np.nan), (-1.0, 1.0), (1.0, np.inf)]:
        with pytest.raises(ValueError, match="sampling"):
            edtmap.distance_transform_edt(mask, sampling=bad)
        with pytest.raises(ValueError, match="anisotropy"):
            edtmap.edt(mask, anisotropy=bad)
        with pytest.raises(ValueError, match="voxel_size"):
            edtmap.obstacle_distance(mask, voxel_size=bad)
    with pytest.raises(TypeError, match="parallel"):
        edtmap.edt(mask, parallel=1.5)


def test_parallel_is_capped_at_the_cores():
    mask = random_mask((20, 30, 25), 0.02, 12)
    want = edt_package.edt(mask)
    for parallel in [10**6, 2**63 - 1, -5]:
        np.testing.assert_array_equal(edtmap.edt(mask, parallel=parallel), want)
