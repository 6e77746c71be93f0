"""The step numbers a user sees: BO steps count from 1 (step 1 is the first BO step, step
n_steps the last) and seed points belong to step 0.

Inside the engine and its journal a decision keeps its 0-based index (``Decision.step``,
``Request.step``; ``PointCommitted.step`` is -1 for a seed point); every output (the HDF5 file
from schema 4, the CLI, the bridge, the view, the reports) shows ``shown(index)``. Files of
schema 1-3 stored the 0-based index; ``from_schema`` converts what they hold.
"""

from __future__ import annotations

import numpy as np

SEED = 0  # the step of the seed points
NOT_CONVERGED = -1  # the file's converged_step attribute when the noise model has not converged
FIRST_SHOWN_SCHEMA = 4  # the first schema version whose files store the shown steps


def shown(index: int | None) -> int | None:
    """The step a user sees for the engine's 0-based step ``index`` (-1, a seed point: 0)."""
    return None if index is None else int(index) + 1


def converged_attr(index: int | None) -> int:
    """The file's ``converged_step`` attribute for the engine's converged step index (None: not yet)."""
    return NOT_CONVERGED if index is None else int(index) + 1


def from_schema(version: int, tables: dict, attrs: dict) -> None:
    """Convert in place what a file of schema ``version`` holds (its "points" and "steps" tables'
    "step" columns and its ``converged_step`` attribute) to the shown steps."""
    if version >= FIRST_SHOWN_SCHEMA:
        return
    for table in ("points", "steps"):
        if "step" in tables.get(table, {}):
            tables[table]["step"] = np.asarray(tables[table]["step"]) + 1
    if "converged_step" in attrs and int(attrs["converged_step"]) >= 0:
        attrs["converged_step"] = int(attrs["converged_step"]) + 1
