"""`noisebo noise-profile FILE [FILE ...] --out PROFILE.yaml`: the posterior of an instrument's
noise law distilled from finished campaigns on it (``noisebo.models.profile``)."""

from __future__ import annotations

import datetime as dt
import os
from pathlib import Path
from typing import TYPE_CHECKING

from noisebo.storage.integrity import CampaignFileError

if TYPE_CHECKING:
    from noisebo.models.profile import NoiseProfile


def noise_measurements(path: Path) -> dict:
    """What a profile takes from one campaign file: its config, driver, seed, start time and
    the points whose noise was measured (t, sample sd, shots)."""
    import numpy as np

    from noisebo.storage.record import read_record

    record = read_record(path)
    points = record.points
    measured = points.noise_measured.astype(bool) & (points.n_shots >= 2)
    x = np.asarray(points.x, dtype=np.float64).reshape(len(points), -1)
    return {
        "file": str(path),
        "config": record.config,
        "driver": record.driver,
        "seed": record.seed,
        "created_utc": str(record.attrs.get("created_utc", "")),
        "x": x[measured],
        "t": points.t.astype(np.float64)[measured],
        "shot_std": points.shot_std.astype(np.float64)[measured],
        "n_shots": points.n_shots.astype(np.float64)[measured],
    }


def _same(campaigns: list[dict], what: str, describe) -> None:
    first = campaigns[0]
    for other in campaigns[1:]:
        if describe(other) != describe(first):
            raise CampaignFileError(
                f"{other['file']} was made with {what} {describe(other)}, {first['file']} with "
                f"{describe(first)}: a profile describes one instrument with one setting"
            )


def _field_kind(field, config) -> str:
    if field is None:
        return "independent of x"
    return f"a field varying {field.varies} over {config.space.dimensions} axes"


def make_profile(files: list[Path]) -> NoiseProfile:
    import numpy as np

    from noisebo import registry
    from noisebo.config import parse_config
    from noisebo.keys import PROFILE, jax_key
    from noisebo.models.profile import (
        FieldCampaign,
        NoiseProfile,
        NotDistillable,
        ProfileCampaign,
        ProfileDriver,
        distil,
        distil_field,
    )
    from noisebo.storage.hdf5 import check_present
    from noisebo.storage.isolated import call_isolated

    campaigns = [call_isolated(noise_measurements, check_present(f), what=str(f)) for f in files]
    _same(campaigns, "the driver", lambda c: (c["driver"]["name"], c["driver"]["version"], c["driver"]["settings"]))
    configs = [parse_config(c["config"], c["file"]) for c in campaigns]
    _same(
        [{**c, "law": cfg.noise_model.mean} for c, cfg in zip(campaigns, configs)], "the noise law", lambda c: c["law"]
    )
    fields = [cfg.noise_model.field for cfg in configs]
    _same(
        [{**c, "field": _field_kind(f, cfg)} for c, f, cfg in zip(campaigns, fields, configs)],
        "the noise",
        lambda c: c["field"],
    )
    pooled = {k: np.concatenate([c[k] for c in campaigns]) for k in ("t", "shot_std", "n_shots")}
    names = ", ".join(str(f) for f in files)
    law = registry.noise_law(configs[0].noise_model.mean)
    try:
        if fields[0] is None:
            posterior = distil(configs[0], law, pooled["t"], pooled["shot_std"], pooled["n_shots"], jax_key(0, PROFILE))
        else:
            parts = [
                FieldCampaign(cfg, c["x"], c["t"], c["shot_std"], c["n_shots"]) for c, cfg in zip(campaigns, configs)
            ]
            posterior = distil_field(parts, law, jax_key(0, PROFILE))
    except NotDistillable as why:
        raise CampaignFileError(f"no noise profile can be made of {names}: {why}") from None
    driver = campaigns[0]["driver"]
    return NoiseProfile(
        driver=ProfileDriver(name=driver["name"], version=driver["version"], settings=driver["settings"]),
        law=configs[0].noise_model.mean,
        field=None if fields[0] is None else fields[0].varies,
        parameters=posterior.parameters,
        correlation=posterior.correlation,
        t_range_s=(float(pooled["t"].min()), float(pooled["t"].max())),
        noise_points=int(pooled["t"].size),
        campaigns=tuple(
            ProfileCampaign(
                file=c["file"],
                config=cfg.name,
                seed=c["seed"],
                created_utc=c["created_utc"],
                noise_points=int(c["t"].size),
            )
            for c, cfg in zip(campaigns, configs)
        ),
        made_utc=dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
    )


def law_text(profile: dict) -> str:
    """A profile's law in one line, from its JSON form: "a0 = 0.1 ± 0.01, a1 = 2 ± 0.05,
    correlation a0,a1 -0.82"."""
    law = ", ".join(f"{name} = {p['mean']:.4g} ± {p['sd']:.2g}" for name, p in profile["parameters"].items())
    return law + "".join(f", correlation {pair} {r:.2f}" for pair, r in profile.get("correlation", {}).items())


def run(args) -> int:
    import yaml

    out = Path(args.out)
    if out.exists():
        raise CampaignFileError(f"{out} already exists; a profile is not overwritten (remove it or name another --out)")
    if not out.parent.is_dir():
        raise CampaignFileError(f"{out.parent} is not a folder; --out names the profile's file")
    profile = make_profile([Path(f) for f in args.files])
    partial = out.with_name(out.name + ".partial")
    partial.write_text(yaml.safe_dump(profile.model_dump(mode="json"), sort_keys=False))
    os.replace(partial, out)
    law = law_text(profile.model_dump(mode="json"))
    print(
        f"{out}: {profile.driver.name} {profile.driver.version}, law {profile.law}: {law} "
        f"(from {profile.noise_points} noise measurements in {len(profile.campaigns)} campaigns)"
    )
    return 0


def add_parser(commands) -> None:
    parser = commands.add_parser("noise-profile", help="distil an instrument's noise law from finished campaigns on it")
    parser.add_argument("files", nargs="+", metavar="FILE", help="campaign files (.h5) of one driver and settings")
    parser.add_argument("--out", required=True, metavar="PROFILE.yaml", help="the profile to write (not overwritten)")
    parser.set_defaults(handler=run)
