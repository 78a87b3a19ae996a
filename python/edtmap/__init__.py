"""edtmap: exact Euclidean distance transforms and volumetric mapping for
robot motion planning.

Distance transforms of numpy arrays, with the call shapes people already
use:

- :func:`distance_transform_edt`, as ``scipy.ndimage.distance_transform_edt``;
- :func:`edt` and :func:`edtsq`, as the ``edt`` package's;
- :func:`obstacle_distance`, edtmap's own convention (nonzero = obstacle).
"""

from ._edtmap import __version__
from ._transforms import distance_transform_edt, edt, edtsq, obstacle_distance

__all__ = ["__version__", "distance_transform_edt", "edt", "edtsq", "obstacle_distance"]
