"""edtmap: exact Euclidean distance transforms and volumetric mapping for
robot motion planning.

Distance transforms of numpy arrays, with the call shapes people already
use:

- :func:`distance_transform_edt`, as ``scipy.ndimage.distance_transform_edt``;
- :func:`edt` and :func:`edtsq`, as the ``edt`` package's;
- :func:`obstacle_distance`, edtmap's own convention (nonzero = obstacle).

The mapping pipeline: :class:`Mapper` (depth images, point clouds, range
images and planar scans in; distances, gradients, states, boxes, the local
EDT and frontiers out; save and load), with the sensor models
:class:`DepthCamera`, :class:`SpinningLidar`, :class:`PointSensor` and
:class:`PlanarLidar`, and :func:`read_recording` for the frames of any
recording edtmap reads.
"""

from ._edtmap import __version__
from ._mapper import (DepthCamera, Mapper, PlanarLidar, PointSensor, Recording, SpinningLidar,
                      read_recording)
from ._transforms import distance_transform_edt, edt, edtsq, obstacle_distance

__all__ = ["__version__", "distance_transform_edt", "edt", "edtsq", "obstacle_distance", "Mapper",
           "DepthCamera", "SpinningLidar", "PointSensor", "PlanarLidar", "Recording", "read_recording"]
