"""Distance transforms of numpy arrays with the call shapes of SciPy and of
the ``edt`` package, plus edtmap's own obstacle convention.

All three run edtmap's exact separable transform (Rust, all cores, the GIL
released). Distances are exact: integer spacings are computed in integer
arithmetic, other spacings in float64.
"""

from __future__ import annotations

import numbers
from typing import Optional, Sequence, Tuple, Union

import numpy as np

from . import _edtmap

__all__ = ["distance_transform_edt", "edt", "edtsq", "obstacle_distance"]

Spacing = Union[None, float, Sequence[float]]


def _grid(array, name: str):
    """Returns ``(c_contiguous_unsigned_view, transposed)`` for the core.

    C-ordered arrays are borrowed as they are; Fortran-ordered ones are
    transposed (a view, no copy) and the results transposed back; other
    strides are copied once. bool and signed integers are viewed as unsigned
    integers of the same width (zero stays zero); floats are compared with 0.
    """
    a = np.asarray(array)
    if a.dtype.kind not in "biuf":
        raise TypeError(f"{name} must hold booleans, integers or floats, not {a.dtype}")
    if a.ndim not in (1, 2, 3):
        raise ValueError(f"{name} must have 1, 2 or 3 dimensions, not {a.ndim} (shape {a.shape})")
    if a.size == 0:
        raise ValueError(f"{name} is empty (shape {a.shape})")
    transposed = False
    if not a.flags.c_contiguous:
        if a.flags.f_contiguous:
            a, transposed = a.T, True
        else:
            a = np.ascontiguousarray(a)
    if a.dtype.kind == "f":
        a = (a != 0).view(np.uint8)
    elif a.dtype.kind == "b":
        a = a.view(np.uint8)
    elif a.dtype.kind == "i" or not a.dtype.isnative:
        a = a.view(np.dtype(f"u{a.dtype.itemsize}"))
    return a, transposed


def _spacing(values: Spacing, ndim: int, name: str) -> Optional[list]:
    """A spacing per axis from a scalar or a sequence; ``None`` stays."""
    if values is None:
        return None
    if isinstance(values, numbers.Real) or np.ndim(values) == 0:
        out = [float(values)] * ndim
    else:
        out = [float(v) for v in np.asarray(values, dtype=np.float64).ravel()]
        if len(out) != ndim:
            raise ValueError(f"{name} has {len(out)} values for an array of {ndim} dimensions")
    for v in out:
        if not (np.isfinite(v) and v > 0):
            raise ValueError(f"{name} values must be finite and positive, got {v}")
    return out


def _threads(parallel, name: str = "parallel") -> int:
    if isinstance(parallel, bool) or not isinstance(parallel, numbers.Integral):
        raise TypeError(f"{name} must be an integer (0: all cores), not {type(parallel).__name__}")
    return max(int(parallel), 0)


def _run(a, transposed, spacing, *, zero_is_obstacle, output, indices="none", black_border=False,
         missing="minus1", threads=0):
    """Calls the core on the C-ordered grid and undoes any transposition."""
    if transposed and spacing is not None:
        spacing = spacing[::-1]
    dist, near = _edtmap.transform(a, spacing, zero_is_obstacle, output, indices, black_border,
                                   missing, threads)
    if transposed:
        if dist is not None:
            dist = dist.T
        if near is not None and indices == "first":
            ndim = near.shape[0]
            near = near[::-1].transpose((0,) + tuple(range(ndim, 0, -1)))
        elif near is not None:
            ndim = near.shape[-1]
            near = near[..., ::-1].transpose(tuple(range(ndim - 1, -1, -1)) + (ndim,))
    return dist, near


def distance_transform_edt(input, sampling: Spacing = None, return_distances: bool = True,
                           return_indices: bool = False, distances=None, indices=None):
    """Exact Euclidean distance transform, as ``scipy.ndimage.distance_transform_edt``.

    For every nonzero element of ``input``, the distance to the nearest zero
    element (zero elements get 0). ``sampling`` is the spacing along each
    axis (a scalar or one value per axis). Distances are float64; indices,
    if requested, are int32 of shape ``(input.ndim,) + input.shape`` holding
    the coordinates of the nearest zero element. ``distances`` and
    ``indices`` may be given as preallocated output arrays, as in SciPy.
    Like SciPy, an input without any zero element measures distances to a
    virtual zero at index -1 of the first axis.

    Accepts 1D, 2D and 3D arrays of any bool, integer or float dtype, in C
    or Fortran order.
    """
    ft_inplace = isinstance(indices, np.ndarray)
    dt_inplace = isinstance(distances, np.ndarray)
    if not return_distances and not return_indices and not ft_inplace and not dt_inplace:
        raise RuntimeError("at least one of return_distances/return_indices must be True")
    a, transposed = _grid(input, "input")
    shape = a.T.shape if transposed else a.shape
    spacing = _spacing(sampling, len(shape), "sampling")
    want_dist = return_distances or dt_inplace
    want_near = return_indices or ft_inplace
    if dt_inplace and (distances.shape != shape or distances.dtype != np.float64):
        raise RuntimeError(f"distances must be a float64 array of shape {shape}")
    if ft_inplace and (indices.shape != (len(shape),) + shape or indices.dtype != np.int32):
        raise RuntimeError(f"indices must be an int32 array of shape {(len(shape),) + shape}")
    dist, near = _run(a, transposed, spacing, zero_is_obstacle=True,
                      output="scipy" if want_dist else "none",
                      indices="first" if want_near else "none",
                      missing="scipy")
    result = []
    if want_dist:
        if dt_inplace:
            np.copyto(distances, dist)
        else:
            result.append(dist)
    if want_near:
        if ft_inplace:
            np.copyto(indices, near)
        else:
            result.append(near)
    if len(result) == 2:
        return tuple(result)
    if len(result) == 1:
        return result[0]
    return None


def _labelled(data, anisotropy, black_border, parallel, squared):
    a, transposed = _grid(data, "data")
    shape = a.T.shape if transposed else a.shape
    spacing = _spacing(anisotropy, len(shape), "anisotropy")
    threads = _threads(parallel)
    output = "float32sq" if squared else "float32"
    if not _edtmap.several_labels(a):
        dist, _ = _run(a, transposed, spacing, zero_is_obstacle=True, output=output,
                       black_border=black_border, threads=threads)
        return dist
    # Several labels: each voxel's distance to the nearest voxel of another
    # label (background included), one transform per label over its
    # bounding box grown by one voxel: every voxel outside the box is of
    # another label and no farther than the box's outer layer.
    # The box's outer layer, where it lies inside the array, is of other
    # labels, so the core's black_border on the box adds the array's own
    # border only: on the other faces the outer layer is nearer.
    grid = a.T if transposed else a
    out = np.zeros(shape, dtype=np.float32)
    labels = np.unique(a)
    for label in labels[labels != 0]:
        where = np.nonzero(grid == label)
        box = tuple(slice(max(int(w.min()) - 1, 0), min(int(w.max()) + 2, n))
                    for w, n in zip(where, shape))
        inside = np.ascontiguousarray(grid[box] == label)
        dist, _ = _run(inside.view(np.uint8), False, spacing, zero_is_obstacle=True,
                       output=output, black_border=black_border, threads=threads)
        out[box][inside] = dist[inside]
    return out


def edt(data, anisotropy: Spacing = None, black_border: bool = False, parallel: int = 0):
    """Euclidean distance transform as the ``edt`` package's ``edt.edt``.

    For every voxel of a nonzero label, the distance to the nearest voxel
    of a different label (0 is background); float32 output of the input's
    shape. ``anisotropy`` is the spacing per axis; ``black_border`` treats
    the outside of the array as background; ``parallel`` is the number of
    threads (0: all cores).
    """
    return _labelled(data, anisotropy, black_border, parallel, squared=False)


def edtsq(data, anisotropy: Spacing = None, black_border: bool = False, parallel: int = 0):
    """Squared distances of :func:`edt` (float32), as ``edt.edtsq``."""
    return _labelled(data, anisotropy, black_border, parallel, squared=True)


def obstacle_distance(obstacles, voxel_size: Spacing = None,
                      return_nearest: bool = False) -> Union[np.ndarray, Tuple[np.ndarray, np.ndarray]]:
    """Distance from every voxel to the nearest obstacle (nonzero element).

    edtmap's own convention, as the command line's ``edtmap edt``: nonzero
    elements are obstacles (distance 0); float32 distances, in units of
    ``voxel_size`` (a scalar or one value per axis; voxels when None),
    ``inf`` everywhere if the array holds no obstacle. With
    ``return_nearest``, also the nearest obstacle's index as int32 of shape
    ``shape + (ndim,)`` (``-1`` where there is none), as ``--nearest``.
    """
    a, transposed = _grid(obstacles, "obstacles")
    shape = a.T.shape if transposed else a.shape
    spacing = _spacing(voxel_size, len(shape), "voxel_size")
    dist, near = _run(a, transposed, spacing, zero_is_obstacle=False, output="float32",
                      indices="last" if return_nearest else "none")
    return (dist, near) if return_nearest else dist
