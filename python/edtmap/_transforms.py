"""Distance transforms of numpy arrays with the call shapes of SciPy and of
the ``edt`` package, plus edtmap's own obstacle convention.

All three run edtmap's exact separable transforms (Rust, all cores, the
GIL released), with no copy of a C- or Fortran-ordered input. The core's
transform keeps each voxel's nearest obstacle (8 bytes per voxel): it
serves indices, and one label of an isotropic grid where the system has
room for it; the distance-only transform computes distances in the output
array itself, for any number of labels, and wherever the core's would not
fit. Distances are exact with integer spacings (integer arithmetic; in
float32 below 2^24 squared voxels) and within float64 rounding otherwise,
except that float32 outputs with non-integer anisotropic spacings are
rounded to float32 after each axis, as the ``edt`` package's are. An array
too large for the memory left raises ``MemoryError``.
"""

from __future__ import annotations

import numbers
import os
from typing import Optional, Sequence, Tuple, Union

import numpy as np

from . import _edtmap

__all__ = ["distance_transform_edt", "edt", "edtsq", "obstacle_distance"]

Spacing = Union[None, float, Sequence[float]]


def _array(array, name: str) -> np.ndarray:
    """``array`` as numpy, checked to hold booleans or numbers."""
    a = np.asarray(array)
    if a.dtype.kind not in "biuf":
        raise TypeError(f"{name} must hold booleans, integers or floats, not {a.dtype}")
    if a.ndim > 3:
        raise ValueError(f"{name} must have 1, 2 or 3 dimensions, not {a.ndim} (shape {a.shape})")
    return a


def _grid(a: np.ndarray, name: str):
    """Returns ``(c_contiguous_view, transposed)`` of a checked, non-empty
    array of 1 to 3 dimensions for the core.

    C-ordered arrays are borrowed as they are; Fortran-ordered ones are
    transposed (a view, no copy) and the results transposed back; other
    strides are copied once. bool and signed integers are viewed as unsigned
    integers of the same width (zero stays zero, equal values stay equal);
    float32 and float64 are passed as they are (other floats converted).
    """
    if a.ndim == 0:
        raise ValueError(f"{name} must have 1, 2 or 3 dimensions, not 0 (shape ())")
    transposed = False
    if not a.flags.c_contiguous:
        if a.flags.f_contiguous:
            a, transposed = a.T, True
        else:
            a = np.ascontiguousarray(a)
    if a.dtype.kind == "f":
        if a.dtype.itemsize not in (4, 8) or not a.dtype.isnative:
            a = a.astype(np.float64 if a.dtype.itemsize > 4 else np.float32)
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
    """Threads for the transform: 0 (or less) for all cores; more than the
    cores available are capped there (the core caps it again)."""
    if isinstance(parallel, bool) or not isinstance(parallel, numbers.Integral):
        raise TypeError(f"{name} must be an integer (0: all cores), not {type(parallel).__name__}")
    return min(max(int(parallel), 0), _cores())


def _cores() -> int:
    """Cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0)) or 1
    except AttributeError:
        return os.cpu_count() or 1


def _run(a, transposed, spacing, *, zero_is_obstacle, output, labels=False, indices="none",
         black_border=False, missing="minus1", threads=0):
    """Calls the core on the C-ordered grid and undoes any transposition."""
    if transposed and spacing is not None:
        spacing = spacing[::-1]
    dist, near = _edtmap.transform(a, spacing, labels, zero_is_obstacle, output, indices, black_border,
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
    or Fortran order; as SciPy, a 0-d input is taken as 1D of one element,
    and an empty input gives empty outputs.
    """
    ft_inplace = isinstance(indices, np.ndarray)
    dt_inplace = isinstance(distances, np.ndarray)
    if not return_distances and not return_indices and not ft_inplace and not dt_inplace:
        raise RuntimeError("at least one of return_distances/return_indices must be True")
    a = np.atleast_1d(_array(input, "input"))
    shape = a.shape
    spacing = _spacing(sampling, len(shape), "sampling")
    want_dist = return_distances or dt_inplace
    want_near = return_indices or ft_inplace
    if dt_inplace and (distances.shape != shape or distances.dtype != np.float64):
        raise RuntimeError(f"distances must be a float64 array of shape {shape}")
    if ft_inplace and (indices.shape != (len(shape),) + shape or indices.dtype != np.int32):
        raise RuntimeError(f"indices must be an int32 array of shape {(len(shape),) + shape}")
    if a.size == 0:
        dist, near = np.zeros(shape), np.zeros((len(shape),) + shape, dtype=np.int32)
    else:
        a, transposed = _grid(a, "input")
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
    # Every label at once: the core splits each line of each pass at the
    # boundaries between labels.
    a = _array(data, "data")
    spacing = _spacing(anisotropy, max(a.ndim, 1), "anisotropy")
    threads = _threads(parallel)
    if a.size == 0 and a.ndim > 0:
        return np.zeros(a.shape, dtype=np.float32)
    a, transposed = _grid(a, "data")
    dist, _ = _run(a, transposed, spacing, zero_is_obstacle=True, labels=True,
                   output="float32sq" if squared else "float32", black_border=black_border,
                   threads=threads)
    return dist


def edt(data, anisotropy: Spacing = None, black_border: bool = False, parallel: int = 0):
    """Euclidean distance transform as the ``edt`` package's ``edt.edt``.

    For every voxel of a nonzero label, the distance to the nearest voxel
    of a different label (0 is background; every other value, integer or
    float, is a label); float32 output of the input's shape, empty for an
    empty input. ``anisotropy`` is the spacing per axis; ``black_border`` treats
    the outside of the array as background; ``parallel`` is the number of
    threads (0: all cores; a larger number than the cores this process may
    use is capped at those cores).
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
    An empty array gives empty outputs.
    """
    a = _array(obstacles, "obstacles")
    spacing = _spacing(voxel_size, max(a.ndim, 1), "voxel_size")
    if a.size == 0 and a.ndim > 0:
        dist, near = np.zeros(a.shape, dtype=np.float32), np.zeros(a.shape + (a.ndim,), dtype=np.int32)
    else:
        a, transposed = _grid(a, "obstacles")
        dist, near = _run(a, transposed, spacing, zero_is_obstacle=False, output="float32",
                          indices="last" if return_nearest else "none")
    return (dist, near) if return_nearest else dist
