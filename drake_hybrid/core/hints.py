"""Types for the type hints of the package (docs/design.md, "Type hints"): numpy only, so that the light
modules the command line imports before Drake (``core.arguments``, ``control.gains``) can use them."""

from typing import Any, Sequence, Union

import numpy as np

# A numpy array of any shape and dtype (float, or object for AutoDiffXd). pydrake's stubs spell their arrays
# ndarray[float64[m, 1]], which numpy's own stubs (>= 2) do not take for a shape: an array hinted with a bare
# np.ndarray then does not match them, this one does (a numpy result handed to pydrake is held in one).
Array = np.ndarray[Any, Any]
# A vector given as numbers in a list or tuple, or as an array.
VectorLike = Union[Sequence[float], Array]
