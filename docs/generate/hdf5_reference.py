"""The HDF5 layout's tables, from the layout module both writers share (``noisebo.storage.layout``):
the schema, the root attributes of a real campaign state, and every table's columns with their
dtype, units and description as the writers store them. A root attribute or per-step array
without words here stops the build."""

from __future__ import annotations

from types import SimpleNamespace

import h5py
import numpy as np

from generate.markdown import code, table

ROOT_ATTRIBUTES = {  # what each root attribute says (the writers give attributes no description of their own)
    "schema": "the schema's name",
    "schema_version": "the layout's version",
    "name": "the config's name",
    "seed": "the campaign's seed",
    "policy": "the acquisition policy",
    "instrument": "the instrument driver's name (`instrument.kind`)",
    "driver_json": "the instrument driver's name, version and complete settings (JSON)",
    "status": "running, completed, aborted, failed or budget_spent",
    "status_reason": "why the status changed, in words",
    "created_utc": "when the campaign started (UTC, ISO 8601)",
    "converged_step": "the BO step at which the noise model converged, from 1; -1: not converged",
    "n_points": "points committed",
    "n_steps": "BO steps decided",
    "n_shots": "shots taken",
    "n_failed_attempts": "failed attempts at shots",
    "budget_s": "the instrument-time budget (s); -1: none",
    "wall_budget_s": "the wall-time budget (s); -1: none",
    "wall_s": "the wall time the campaign had run (s) as of its last committed point or status, the time between a stop and its resume left out",
    "config_json": "the full config (JSON)",
    "versions_json": "Python's and the packages' versions (JSON)",
}
ARRAY_SHAPES = {  # the per-step arrays' shapes, with the step axis first (layout.array_shapes: the rest)
    "acq_map": "(n_steps, n_x, n_t); (n_steps, m) for d > 1 axes: the best over t at each reference point",
    "f_mean": "(n_steps, n_x); (n_steps, m) for d > 1",
    "f_var": "(n_steps, n_x); (n_steps, m) for d > 1",
    "noise_mean": "(n_steps, n_t)",
    "noise_var": "(n_steps, n_t)",
    "t_opt_map": "(n_steps, m)",
}
GROUP_ATTRIBUTES = {  # what the attributes of /summary say
    "t_opt": "the final predicted optimal t (s; with a noise field, the t maximising the reward averaged over x)",
    "hyperparameters_json": "the final models' fitted hyperparameters (JSON)",
}
X_SHAPE = "x: (n, d) for d > 1 axes, in the order of `space.axes`"


class Undocumented(ValueError):
    """A part of the layout that this page has no words for."""


def checked(words: dict, names, what: str) -> None:
    missing, stale = set(names) - set(words), set(words) - set(names)
    if missing or stale:
        raise Undocumented(f"{what}: no words for {sorted(missing)}; words for what is gone: {sorted(stale)}")


def fresh_state():
    """A campaign as it starts, for the root attributes it writes."""
    from noisebo.campaign import engine
    from noisebo.config import CampaignConfig
    from noisebo.events import DriverInfo

    return engine.start(engine.new_campaign(CampaignConfig(), 0, DriverInfo("forrester", "0", {}), {}, "2026-01-01"))


def root_table(layout) -> str:
    attrs = layout.root_attrs(fresh_state())
    checked(ROOT_ATTRIBUTES, attrs, "root attributes")
    mutable = set(layout.MUTABLE_ATTRS)
    rows = [
        (
            code(name),
            type(value).__name__,
            ROOT_ATTRIBUTES[name] + (" (running file: in `/committed`)" if name in mutable else ""),
        )
        for name, value in attrs.items()
    ]
    return table(["attribute", "type", "meaning"], rows)


def column_table(layout, columns: dict, extra: list[tuple] = ()) -> str:
    """/points or /steps: name, dtype, units, description."""
    rows = [
        (code(name), layout.column_dtype(name, units).name, units, description)
        for name, (units, description) in columns.items()
    ]
    return table(["column", "dtype", "units", "description"], rows + list(extra))


def typed_table(columns, text: dict, text_name: str = "text") -> str:
    """/shots or /failures: columns with their own dtype, then the text columns."""
    rows = [(code(name), np.dtype(dtype).name, units, description) for name, dtype, units, description in columns]
    rows += [(code(name), text_name, "text", description) for name, description in text.items()]
    return table(["column", "dtype", "units", "description"], rows)


def written_table(fill, *args) -> str:
    """The datasets ``fill`` writes into an empty in-memory file, as the file stores them, and the
    attributes of its groups."""
    with h5py.File("layout.h5", "w", driver="core", backing_store=False) as f:
        fill(f, *args)
        rows: list[tuple] = []
        f.visititems(
            lambda path, obj: (
                rows.append((code("/" + path), obj.dtype.name, obj.attrs["units"], obj.attrs["description"]))
                if isinstance(obj, h5py.Dataset)
                else None
            )
        )
        attrs = {f"/{group}": dict(f[group].attrs) for group in f if f[group].attrs}
    text = table(["dataset", "dtype", "units", "description"], rows)
    for group, values in attrs.items():
        checked(GROUP_ATTRIBUTES, values, f"attributes of {group}")
        text += f"\nAttributes of {code(group)}:\n\n" + table(
            ["attribute", "type", "meaning"],
            [(code(name), type(value).__name__, GROUP_ATTRIBUTES[name]) for name, value in values.items()],
        )
    return text


def summary_stub():
    one = np.zeros(1)
    return SimpleNamespace(
        summary=SimpleNamespace(
            t_opt=1.0, hyperparameters={}, f_mean=one, f_var=one, noise_fine=one, t_opt_map=one, noise_map=one
        )
    )


def grid_stub():
    from noisebo.config import CampaignConfig

    return SimpleNamespace(config=CampaignConfig())


def _instrument_words(layout, table: str) -> str:
    return f"{layout.INSTRUMENT_TEXT[table]} (a campaign of several named instruments only)"


def _instrument_row(layout, table: str) -> tuple:
    return (code("instrument"), "text", "text", _instrument_words(layout, table))


def page() -> str:
    """The generated tables of the HDF5 layout page."""
    from noisebo.storage import layout

    checked(ARRAY_SHAPES, layout.ARRAY_COLUMNS, "per-step arrays")
    step_arrays = [
        (code(name), layout.array_dtype(name).name, units, f"{description}; {ARRAY_SHAPES[name]}")
        for name, (units, description) in layout.ARRAY_COLUMNS.items()
    ]
    hyper = [
        (
            code("hyperparameters/<name>"),
            "float64",
            "",
            "each fitted hyperparameter per step (MAP or posterior mean; A0, A1 in units of f)",
        )
    ]
    return "\n".join(
        [
            f"Schema {code(layout.SCHEMA)}, version {layout.SCHEMA_VERSION}; files of versions "
            f"{', '.join(map(str, layout.READABLE_VERSIONS))} are read; checksums from version {layout.CHECKSUMMED_FROM}.\n",
            "### Root attributes\n",
            root_table(layout),
            f"### `/points`\n\nOne row per point, (n_points,), in the order the points were committed; {X_SHAPE}.\n",
            column_table(
                layout,
                layout.POINT_COLUMNS,
                [(code("step"), "int32", *layout.POINT_STEP), (code("index"), "int32", *layout.POINT_INDEX)]
                + [_instrument_row(layout, "points")]
                + [
                    (
                        code("committed_after"),
                        "int32",
                        layout.POINT_COMMITTED_AFTER[0],
                        f"{layout.POINT_COMMITTED_AFTER[1]} (a campaign of several named instruments only)",
                    )
                ],
            ),
            f"### `/steps`\n\nOne row per BO step, (n_steps,); {X_SHAPE}.\n",
            column_table(layout, layout.STEP_COLUMNS, hyper + step_arrays + [_instrument_row(layout, "steps")]),
            f"### `/shots`\n\nOne row per shot, (n_shots,); {X_SHAPE}.\n",
            typed_table(layout.SHOT_COLUMNS, layout.SHOT_TEXT | {"instrument": _instrument_words(layout, "shots")}),
            "### `/shots/fit`\n\nResonance sweeps only: each sweep's SHO fit, (n_shots,).\n",
            table(
                ["column", "dtype", "units", "description"],
                [(code(n), "float64", u, d) for n, (u, d) in layout.FIT_UNITS.items()]
                + [(code("note"), "text", "text", layout.FIT_NOTE)],
            ),
            f"### `/failures`\n\nOne row per failed attempt, (n_failed,); {X_SHAPE}. {layout.FAILURES_DESCRIPTION[:1].upper()}"
            f"{layout.FAILURES_DESCRIPTION[1:]}.\n",
            typed_table(
                layout.FAILURE_COLUMNS, layout.FAILURE_TEXT | {"instrument": _instrument_words(layout, "failures")}
            ),
            f"### `/spectra`\n\n`/spectra/point_NNNN` (shots, rows, samples), float32: {layout.SPECTRA_DESCRIPTION} "
            f"({layout.SPECTRA_ROWS}).\n",
            "### `/grid`\n\nThe candidate grids: `x` (n_x,) for one axis; for d > 1 axes the m reference points, (m, d) "
            "(two axes: the n0 x n1 display grid, axis 0 slowest, so `reshape(n0, n1)` is the image; more: a Halton "
            "set); `t` (n_t,); `t_fine` (2049,), where the optimal t is searched.\n",
            written_table(layout.fill_grid, grid_stub()),
            "### `/summary`\n\nThe final models, once the campaign has them; `t_opt_map` and `noise_map` with a noise "
            "field only.\n",
            written_table(layout.fill_summary, summary_stub()),
        ]
    )
