# Type stubs of the compiled module (python/src/lib.rs); the public API is acetab/__init__.py.
from typing import Any, Dict, Optional, Tuple

import numpy as np
import numpy.typing as npt

class AcetabError(Exception):
    """The engine refused the input or could not stand behind a result."""

def reconstruct_case_json(
    path: str, out: Optional[str], force: bool, options_json: str
) -> str: ...
def reconstruct_json(
    case_json: str, options_json: str
) -> Tuple[npt.NDArray[np.float64], npt.NDArray[np.int64], str]: ...
def align(
    a: npt.NDArray[np.float64],
    b: npt.NDArray[np.float64],
    mode: str,
    samples: int,
    anchor: float,
) -> Dict[str, Any]: ...
def simulate_json(options_json: str) -> str: ...
def version() -> str: ...
