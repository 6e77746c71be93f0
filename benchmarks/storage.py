"""Storage cost per committed point as a campaign grows: the old whole-file rewrite against appending.

    python benchmarks/storage.py [--n 100,500,1000,2000] [--repeats 20] [--old-repeats 3]
                                 [--kind scalar,spectra] [--json benchmarks/results/storage.json]
    python benchmarks/storage.py --checksums [--n ...] [--repeats ...] [--kind ...] [--json ...]

A synthetic campaign goes through the real engine events and ``storage.recorder.Recorder`` (the
journal fsynced per commit, as ``noisebo run`` commits them: a decision, each shot, the last shot
with its point): "scalar" is Forrester-like (forrester.yaml's 200 x 100 grid, 30 shots per seed
point, then 3; one failed attempt every 25 points), "spectra" PFM-like (pfm.yaml's grid, each
shot a float32 sweep of 3 rows x 10 kHz x t, t around 0.47 s). For each n it prints the median
time of all Recorder.commit calls of one point (journal + HDF5; the decisions themselves are
not made, they are synthetic) over the points that follow n, and the file's size at n:

- new: the campaign grown point by point to the largest n with appends (``storage.live``);
  its file is the running (uncompressed) layout; "finished" is the size of the finished file
  that the end of the run writes (``write_snapshot``) at that n.
- old: the recorder as it was, rewriting the whole file after every point (``write_snapshot``),
  timed over ``--old-repeats`` points after n (on a state built in memory up to n).

``--checksums`` instead grows the campaign twice, a point of each in turn, once with the running
file's tables checksummed (fletcher32, as noisebo writes them) and once without, and prints both
medians and their ratio.
"""

from __future__ import annotations

import noisebo.cli  # noqa: F401 - first: one OpenBLAS thread for this process, before numpy loads (as the command line)
import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

from noisebo.acquisition.records import Decision  # noqa: E402
from noisebo.campaign import engine  # noqa: E402
from noisebo.config import CampaignConfig, load_config  # noqa: E402
from noisebo.events import (  # noqa: E402
    Decided,
    DriverInfo,
    Event,
    PointCommitted,
    ShotFailed,
    ShotTaken,
    Started,
)
from noisebo.reduction import Reading, ShotValue  # noqa: E402
from noisebo.sho import SHOFit  # noqa: E402
from noisebo.state import Point  # noqa: E402
from noisebo.storage import event_codec, live  # noqa: E402
from noisebo.storage.hdf5 import write_snapshot  # noqa: E402
from noisebo.storage.journal import JournalWriter  # noqa: E402
from noisebo.storage.recorder import Recorder, journal_path  # noqa: E402

HYPERPARAMETERS = ("noise.a0", "noise.a1", "primary.amplitude", "primary.length")
CONVERGED_AT = 5  # BO step from which points get shots_after shots


def started(config: CampaignConfig, seed: int = 0) -> Started:
    return Started(
        config, seed, DriverInfo("synthetic", "0", {}), {"python": sys.version.split()[0]}, "2026-01-01T00:00:00+00:00"
    )


def decision(config: CampaignConfig, step: int, rng: np.random.Generator) -> Decision:
    """A synthetic BO step with arrays of the config's grid: acq_map (n_x, n_t) float32, f_* (n_x,), noise_* (n_t,)."""
    n_x, n_t, s = config.space.n_x, config.space.n_t, config.space
    converged = step >= CONVERGED_AT
    return Decision(
        step=step,
        x=float(rng.uniform(s.x_min, s.x_max)),
        t=float(rng.uniform(s.t_min, s.t_max)),
        acq_value=float(rng.normal()),
        shots=config.schedule.shots_after if converged else config.schedule.shots_before,
        measure_noise=not converged,
        noise_at_t=float(rng.uniform(0.1, 1)),
        t_opt=float(rng.uniform(s.t_min, s.t_max)),
        converged=converged,
        hyperparameters={k: float(rng.normal()) for k in HYPERPARAMETERS},
        acq_map=rng.normal(size=(n_x, n_t)).astype(np.float32),
        f_mean=rng.normal(size=n_x),
        f_var=rng.uniform(size=n_x),
        noise_mean=rng.uniform(size=n_t),
        noise_var=rng.uniform(size=n_t),
        latency_s=float(rng.uniform(0.1, 1)),
    )


def sweep(t: float, rng: np.random.Generator) -> np.ndarray:
    """A PFM-like raw sweep (3, 10 kHz x t) float32: frequency Hz, amplitude pm, phase deg."""
    n = max(8, int(round(10_000 * t)))
    freq = np.linspace(367_000.0, 377_000.0, n)
    return np.stack([freq, rng.normal(50.0, 5.0, n), rng.normal(90.0, 3.0, n)]).astype(np.float32)


def shot_value(reading: Reading, k: int, spectra: bool, reject: bool) -> ShotValue:
    if reject:
        return ShotValue(float("nan"), False, "non-finite reading", None)
    if not spectra:
        return ShotValue(float(reading.value), True, "", None)
    amplitude = float(np.mean(reading.spectrum[1]))
    fit = SHOFit(
        value=amplitude,
        amplitude=amplitude,
        amplitude_se=0.1,
        resonance_hz=372_000.0 + k,
        resonance_se=5.0,
        q=250.0,
        q_se=3.0,
        phase_deg=90.0,
        sign=1.0,
        ok=True,
        reason="" if k % 7 else "nominal resonance used: the free fit did not converge",
    )
    return ShotValue(amplitude, True, "", fit)


def point_commits(
    config: CampaignConfig,
    index: int,
    seed: int = 0,
    spectra: bool = False,
    fail_every: int = 25,
    reject_every: int = 0,
) -> list[list[Event]]:
    """The event batches one point commits, in order, as a campaign loop commits them: its
    decision (a BO point), a failed attempt at its first shot (every ``fail_every``-th point),
    each shot, the last with the point. ``reject_every``: every such shot of the point is rejected."""
    rng = np.random.default_rng([seed, index])
    n_seed = config.schedule.n_seed
    batches: list[list[Event]] = []
    if index >= n_seed:
        d = decision(config, index - n_seed, rng)
        batches.append([Decided(d)])
        x, t, n_shots, step = d.x, d.t, d.shots, d.step
    else:
        s = config.space
        x, t, n_shots, step = (
            (float(rng.uniform(s.x_min, s.x_max)),),
            float(rng.uniform(s.t_min, s.t_max)),
            config.schedule.shots_before,
            -1,
        )
    if spectra:
        t = float(np.clip(rng.lognormal(np.log(0.47), 0.3), config.space.t_min, config.space.t_max))
    if fail_every and index % fail_every == fail_every - 1:
        batches.append([ShotFailed(index, 0, x, t, "instrument error", f"synthetic failure at point {index}")])
    shots, values = [], []
    for k in range(n_shots):
        reading = Reading(None, sweep(t, rng), "sho") if spectra else Reading(float(rng.normal(1.0, 0.3)))
        shots.append(ShotTaken(index, k, x, t, reading))
        values.append(shot_value(reading, k, spectra, bool(reject_every) and k % reject_every == reject_every - 1))
        batches.append([shots[-1]])
    ok = np.asarray([v.value for v in values if v.ok])
    sd = float(ok.std(ddof=1)) if ok.size > 1 else float("nan")
    point = Point(x, t, float(ok.mean()), sd, int(ok.size), sd if ok.size > 1 else 0.5, bool(ok.size > 1))
    batches[-1].append(PointCommitted(index, step, point, tuple(values)))
    return batches


def state_at(config: CampaignConfig, n: int, spectra: bool, seed: int = 0):
    """The engine state of the synthetic campaign after its first n points (in memory)."""
    state = engine.start(started(config, seed))
    for i in range(n):
        for batch in point_commits(config, i, seed, spectra):
            state = engine.apply_all(state, batch)
    return state


class Timed:
    """Recorder mixin: the seconds spent bringing the HDF5 file up to date (``hdf5_s``)."""

    hdf5_s = 0.0

    def snapshot(self) -> None:
        started_at = time.perf_counter()
        super().snapshot()
        self.hdf5_s += time.perf_counter() - started_at


class AppendingRecorder(Timed, Recorder):
    """The recorder as it is: the running file grown in place."""


class RewritingRecorder(Timed, Recorder):
    """The recorder as it was before appending: the whole file rewritten after every point."""

    def snapshot(self) -> None:
        started_at = time.perf_counter()
        write_snapshot(self.h5_path, self.state)
        self.hdf5_s += time.perf_counter() - started_at


def commit_point(recorder, config: CampaignConfig, index: int, spectra: bool) -> tuple[float, float]:
    """Commit one point's batches; the seconds all its Recorder.commit calls took, and the HDF5 part of them."""
    total, hdf5_before = 0.0, recorder.hdf5_s
    for batch in point_commits(config, index, 0, spectra):
        started_at = time.perf_counter()
        recorder.commit(recorder.state, batch)
        total += time.perf_counter() - started_at
    return total, recorder.hdf5_s - hdf5_before


def grow_new(config: CampaignConfig, sizes: list[int], repeats: int, spectra: bool, folder: Path) -> dict:
    """{n: {"s", "hdf5_s": medians per point over the ``repeats`` points after n, "bytes": the
    running file's size at n, "finished_bytes": the finished file's}}."""
    path, finished = folder / "new.h5", folder / "finished.h5"
    out, at = {}, {}
    with AppendingRecorder.create(path, started(config)) as recorder:
        times = []
        for i in range(max(sizes) + repeats):
            if i in sizes:
                out[i], at[i] = {"bytes": path.stat().st_size}, recorder.state
            if i - repeats in sizes:  # after the timed points: its fsync must not slow them
                write_snapshot(finished, at[i - repeats])
                out[i - repeats]["finished_bytes"] = finished.stat().st_size
            times.append(commit_point(recorder, config, i, spectra))
    write_snapshot(finished, at[max(sizes)])
    out[max(sizes)]["finished_bytes"] = finished.stat().st_size
    finished.unlink()
    for n in sizes:
        total, hdf5 = zip(*times[n : n + repeats])
        out[n] |= {"s": statistics.median(total), "hdf5_s": statistics.median(hdf5)}
    return out


class UncheckedRecorder(AppendingRecorder):
    """The recorder as it is, its running file's tables without the fletcher32 checksum."""

    def snapshot(self) -> None:
        live.CHECKSUMS = False
        try:
            super().snapshot()
        finally:
            live.CHECKSUMS = True


def grow_pair(config: CampaignConfig, sizes: list[int], repeats: int, spectra: bool, folder: Path) -> dict:
    """The same campaign grown twice, point by point in turn, with and without the tables'
    checksums: {n: {"checked_s", "unchecked_s": medians per point over the ``repeats`` points
    after n, "checked_bytes", "unchecked_bytes": the running files' sizes at n}}."""
    recorders = {
        "checked": AppendingRecorder.create(folder / "checked.h5", started(config)),
        "unchecked": UncheckedRecorder.create(folder / "unchecked.h5", started(config)),
    }
    times: dict[str, list[float]] = {name: [] for name in recorders}
    out: dict[int, dict] = {}
    try:
        for i in range(max(sizes) + repeats):
            order = list(recorders.items()) if i % 2 else list(recorders.items())[::-1]
            for name, recorder in order:
                if i in sizes:
                    out.setdefault(i, {})[f"{name}_bytes"] = recorder.h5_path.stat().st_size
                times[name].append(commit_point(recorder, config, i, spectra)[0])
    finally:
        for recorder in recorders.values():
            recorder.close()
    for n in sizes:
        out[n] |= {f"{name}_s": statistics.median(times[name][n : n + repeats]) for name in recorders}
    return out


def compare_checksums(configs: dict, kinds: list[str], sizes: list[int], repeats: int) -> list[dict]:
    """Print and return the commit time per point with and without the tables' checksums."""
    rows = []
    for kind in kinds:
        config = configs[kind].with_overrides(schedule={"n_steps": max(sizes) + repeats})
        print(
            f"{kind}: Recorder.commit per point (journal + HDF5), median of {repeats} points after n, the two "
            "campaigns grown in turn",
            flush=True,
        )
        print(
            f"{'n':>6} {'no checksums ms':>16} {'fletcher32 ms':>14} {'ratio':>6} {'file MB':>8} {'file MB':>8}",
            flush=True,
        )
        with tempfile.TemporaryDirectory(prefix="noisebo-storage-") as tmp:
            pair = grow_pair(config, sizes, repeats, kind == "spectra", Path(tmp))
        for n in sizes:
            p = pair[n]
            row = {
                "kind": kind,
                "n": n,
                "unchecked_ms": p["unchecked_s"] * 1e3,
                "checked_ms": p["checked_s"] * 1e3,
                "ratio": p["checked_s"] / p["unchecked_s"],
                "unchecked_mb": p["unchecked_bytes"] / 1e6,
                "checked_mb": p["checked_bytes"] / 1e6,
            }
            rows.append(row)
            print(
                f"{n:>6} {row['unchecked_ms']:>16.2f} {row['checked_ms']:>14.2f} {row['ratio']:>6.3f} "
                f"{row['unchecked_mb']:>8.2f} {row['checked_mb']:>8.2f}",
                flush=True,
            )
    return rows


def old_at(config: CampaignConfig, n: int, repeats: int, spectra: bool, folder: Path, state) -> dict:
    """The old recorder from the in-memory ``state`` of n points: {"s", "hdf5_s": medians per
    point over ``repeats`` points after n, "bytes": its file's size at n}."""
    path = folder / f"old{n}.h5"
    writer = JournalWriter.create(journal_path(path), event_codec.encode(started(config)))
    with RewritingRecorder(path, writer, state) as recorder:
        recorder.snapshot()
        size = path.stat().st_size
        total, hdf5 = zip(*(commit_point(recorder, config, n + k, spectra) for k in range(repeats)))
    path.unlink()
    journal_path(path).unlink()
    return {"s": statistics.median(total), "hdf5_s": statistics.median(hdf5), "bytes": size}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", default="100,500,1000,2000", help="comma-separated numbers of points")
    parser.add_argument("--repeats", type=int, default=20, help="points timed after each n (new)")
    parser.add_argument("--old-repeats", type=int, default=3, help="points timed after each n (old)")
    parser.add_argument("--kind", default="scalar,spectra")
    parser.add_argument("--json", type=Path, default=None, help="also write the figures here")
    parser.add_argument(
        "--checksums",
        action="store_true",
        help="instead: the commit time with and without the tables' fletcher32 checksums",
    )
    args = parser.parse_args(argv)
    sizes = [int(v) for v in args.n.split(",")]
    configs = {
        "scalar": load_config(ROOT / "data/configs/forrester.yaml"),
        "spectra": load_config(ROOT / "data/configs/pfm.yaml"),
    }
    if args.checksums:
        rows = compare_checksums(configs, args.kind.split(","), sizes, args.repeats)
        if args.json:
            args.json.write_text(json.dumps(rows, indent=1))
        return 0
    rows = []
    for kind in args.kind.split(","):
        config, spectra = configs[kind], kind == "spectra"
        config = config.with_overrides(schedule={"n_steps": max(sizes) + args.repeats})
        print(
            f"{kind}: grid {config.space.n_x} x {config.space.n_t}; per point: Recorder.commit of its decision, "
            f"shots and point (journal + HDF5), median",
            flush=True,
        )
        print(
            f"{'n':>6} {'old ms':>8} {'of which HDF5':>13} {'new ms':>7} {'of which HDF5':>13} {'old file':>9} "
            f"{'new file':>9} {'finished':>9}",
            flush=True,
        )
        with tempfile.TemporaryDirectory(prefix="noisebo-storage-") as tmp:
            new = grow_new(config, sizes, args.repeats, spectra, Path(tmp))
            state, built = engine.start(started(config)), 0
            for n in sizes:
                for i in range(built, n):
                    for batch in point_commits(config, i, 0, spectra):
                        state = engine.apply_all(state, batch)
                built = n
                old = old_at(config, n, args.old_repeats, spectra, Path(tmp), state)
                row = {
                    "kind": kind,
                    "n": n,
                    "old_ms": old["s"] * 1e3,
                    "old_hdf5_ms": old["hdf5_s"] * 1e3,
                    "new_ms": new[n]["s"] * 1e3,
                    "new_hdf5_ms": new[n]["hdf5_s"] * 1e3,
                    "old_mb": old["bytes"] / 1e6,
                    "new_mb": new[n]["bytes"] / 1e6,
                    "finished_mb": new[n]["finished_bytes"] / 1e6,
                }
                rows.append(row)
                print(
                    f"{n:>6} {row['old_ms']:>8.1f} {row['old_hdf5_ms']:>13.1f} {row['new_ms']:>7.1f} "
                    f"{row['new_hdf5_ms']:>13.1f} {row['old_mb']:>7.1f}MB {row['new_mb']:>7.1f}MB "
                    f"{row['finished_mb']:>7.1f}MB",
                    flush=True,
                )
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
