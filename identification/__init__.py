"""Identification of the contact parameters of a loop sorter from its records.

The package is four layers, each importing only from the ones below it:

- ``optim``: the optimisers (Complex-RF serial and parallel, their result
  and journal), knowing nothing of sorters;
- ``objective``: the identification problem (a record, a model, its
  objective), joint problems of several records, the declared noise, the
  Jacobian and the intervals;
- ``pipeline``: the stages of an identification (the global search, window
  growth, local refinement, the shrink stage, intervals and profiles), the
  driver that runs them from the records (the front door,
  :func:`identify_records`) and the campaign over many sorters;
- ``loop``: the closed loop on top: the residual, the catalogue of effects
  the model lacks, their attribution, test and verdict.
"""

from .optim.complex_rf import minimize_complex, parse_bounds
from .optim.complex_rfp import dask_map, minimize_complex_parallel
from .optim.optim_result import ComplexHistory, ComplexResult
from .pipeline.driver import build_problem, identify_records
from .pipeline.settings import Settings, load_settings

__all__ = [
    "identify_records",
    "build_problem",
    "Settings",
    "load_settings",
    "minimize_complex",
    "minimize_complex_parallel",
    "dask_map",
    "parse_bounds",
    "ComplexResult",
    "ComplexHistory",
]
