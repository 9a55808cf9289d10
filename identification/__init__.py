"""Identification of the contact parameters (design brief section 5).

The optimisers: :func:`minimize_complex` (Complex-RF, serial reference) and
:func:`minimize_complex_parallel` (Complex-RFP, several candidates per round).
"""

from .complex_rf import minimize_complex, parse_bounds
from .complex_rfp import dask_map, minimize_complex_parallel
from .optim_result import ComplexHistory, ComplexResult

__all__ = [
    "minimize_complex",
    "minimize_complex_parallel",
    "dask_map",
    "parse_bounds",
    "ComplexResult",
    "ComplexHistory",
]
