"""Rerun adapter: a campaign's frames logged to a recording (an .rrd file, a live viewer, or both).

Visualisation is a non-critical sink: it never stops or slows a campaign. Every logging call is
guarded; the first failure is reported once (through ``warn``) and the view switches itself off.
A live viewer is streamed to only if its address answers a TCP connect within half a second, so an
absent viewer costs at most that, once.

Entities (timeline ``step``, see ``view.frames``; live campaigns also carry ``wall``):
    acquisition/map      the acquisition over the (x, t) grid as an image (t upwards)
    acquisition/points   measured points on that image, coloured by the step that measured them
                         (with several instruments, by the instrument: f/points and noise/points too)
    f/{mean,band,truth,points}, noise/{mean,band,law,points}, reward/{curve,t_opt}
                         curves in plot boxes, each with its axes (f/axes, noise/axes: lines,
                         ticks at round values, the axes' names and units)
    spectrum/{data,fit}  PFM: the latest sweep and its SHO fit
    traces/*             t_opt_s, a0, a1, latency_s, measurement_time_s as scalars
    campaign/points      the measured points in raw units (columns x, t, value, noise, from_step;
                         instrument, with several)
    log                  one text line per decision
"""

from __future__ import annotations

import os
import socket
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Callable
from urllib.parse import urlparse

import numpy as np

from noisebo.config import CampaignConfig
from noisebo.state import format_position
from noisebo.view.area import as_image
from noisebo.view.frames import Curve, Frame
from noisebo.view.style import instrument_colours, step_colours

if TYPE_CHECKING:
    from rerun import RecordingStream
    from rerun.sinks import LogSinkLike

BOX_W, BOX_H = 300.0, 150.0
TRACES = ("t_opt_s", "a0", "a1", "latency_s", "measurement_time_s")
DEFAULT_LIVE = "rerun+http://127.0.0.1:9876/proxy"
IN_FLIGHT_ALPHA = 110  # of 255: a point in flight is drawn pale, the measured ones solid


def colour_by_step(steps: np.ndarray, n_steps: int) -> np.ndarray:
    """RGB uint8 (n, 3) of ``style.step_colours``."""
    return (step_colours(steps, n_steps)[:, :3] * 255).astype(np.uint8)


def point_colours(points: dict, config: CampaignConfig, rows=slice(None)) -> np.ndarray:
    """RGB uint8 (n, 3) of the ``rows`` of a frame's points: by instrument for a campaign of
    several (``style.instrument_colours``, the step in each point's label), else by step."""
    if config.instruments is not None:
        names = np.asarray(points["instrument"], dtype=object)[rows]
        return (instrument_colours(names, config.instrument_names)[:, :3] * 255).astype(np.uint8)
    return colour_by_step(np.asarray(points["frame"])[rows], config.schedule.n_steps)


def acquisition_image(acq_map: np.ndarray) -> np.ndarray:
    """(n_t, n_x, 3) uint8 viridis image of an (n_x, n_t) map, row 0 = longest t (t upwards)."""
    from matplotlib import colormaps

    a = np.asarray(acq_map, dtype=np.float64).T[::-1]
    finite = np.isfinite(a)
    lo, hi = (a[finite].min(), a[finite].max()) if finite.any() else (0.0, 1.0)
    scaled = np.where(finite, (a - lo) / (hi - lo if hi > lo else 1.0), 0.0)
    return (colormaps["viridis"](scaled)[..., :3] * 255).astype(np.uint8)


def colour_image(values: np.ndarray, cmap: str = "viridis", limits: tuple[float, float] | None = None) -> np.ndarray:
    """(rows, columns, 3) uint8 image of a 2-D array through a matplotlib colour map, scaled to
    ``limits`` (default: the finite values' range); non-finite values are drawn as the lowest."""
    from matplotlib import colormaps

    a = np.asarray(values, dtype=np.float64)
    finite = np.isfinite(a)
    lo, hi = limits or ((a[finite].min(), a[finite].max()) if finite.any() else (0.0, 1.0))
    scaled = np.clip(np.where(finite, (a - lo) / (hi - lo if hi > lo else 1.0), 0.0), 0.0, 1.0)
    return (colormaps[cmap](scaled)[..., :3] * 255).astype(np.uint8)


class Box:
    """Maps data (u, v) into a BOX_W x BOX_H plot box, v upwards (2D views draw y downwards).
    ``floor``: the lowest v the box shows (0 for a standard deviation), padding or not."""

    width, height, inset = BOX_W, BOX_H, 0.0

    def __init__(self, u_range: tuple[float, float], v_range: tuple[float, float], floor: float = -np.inf):
        self.u0, self.u1 = u_range
        lo, hi = v_range
        pad = 0.05 * (hi - lo if hi > lo else 1.0)
        self.v0, self.v1 = max(lo - pad, floor), hi + pad

    def __call__(self, u, v) -> np.ndarray:
        span_u, span_v = self.width - 2 * self.inset, self.height - 2 * self.inset
        u = self.inset + (np.asarray(u, dtype=np.float64) - self.u0) / (self.u1 - self.u0 or 1.0) * span_u
        v = self.inset + (1.0 - (np.asarray(v, dtype=np.float64) - self.v0) / (self.v1 - self.v0 or 1.0)) * span_v
        return np.stack(np.broadcast_arrays(u, v), axis=-1)


class ImageBox(Box):
    """Maps data (u, v) onto an image of ``n_u`` x ``n_v`` pixels whose first and last pixel
    centres are the ranges' ends (the grid's first and last values), v upwards."""

    def __init__(self, u_range: tuple[float, float], v_range: tuple[float, float], n_u: int, n_v: int):
        self.u0, self.u1 = u_range
        self.v0, self.v1 = v_range
        self.width, self.height, self.inset = float(n_u), float(n_v), 0.5


def ticks(low: float, high: float, count: int = 5) -> np.ndarray:
    """Round values from ``low`` to ``high`` for an axis's ticks, about ``count`` of them (steps
    of 1, 2 or 5 times a power of ten)."""
    if not high > low:
        return np.array([low])
    raw = (high - low) / count
    power = 10.0 ** np.floor(np.log10(raw))
    step = power * next(m for m in (1.0, 2.0, 5.0, 10.0) if m * power >= raw)
    first = np.ceil(low / step - 1e-9) * step
    return np.round(np.arange(first, high + 1e-9 * step, step), 12) + 0.0  # no -0


def reachable(url: str, timeout_s: float = 0.5) -> bool:
    """Whether something accepts TCP connections at the url's host and port."""
    parsed = urlparse(url)
    try:
        with socket.create_connection((parsed.hostname or "127.0.0.1", parsed.port or 9876), timeout=timeout_s):
            return True
    except OSError:
        return False


class RerunView:
    """Logs frames of one campaign to a Rerun recording.

    ``rrd``: file to record to (None: none); ``live``: None, "spawn" (start a local viewer) or a
    gRPC url such as ``rerun+http://127.0.0.1:9876/proxy``; ``truth`` (x grid values) and
    ``noise_law`` (t grid values) are drawn when the instrument knows them; ``wall_clock`` also
    stamps each frame with the time it was logged."""

    def __init__(
        self,
        config: CampaignConfig,
        name: str,
        rrd: Path | None = None,
        live: str | None = None,
        truth: np.ndarray | None = None,
        noise_law: Callable | None = None,
        warn: Callable[[str], None] = print,
        wall_clock: bool = True,
    ):
        from noisebo.instruments.registry import description

        self.config, self.warn, self.wall_clock = config, warn, wall_clock
        self._described = description(config.instrument.kind)
        self.truth, self.noise_law = truth, noise_law
        self.enabled = True
        self._f_range: tuple[float, float] | None = None
        self._noise_range: tuple[float, float] | None = None
        self.stream: RecordingStream | None = None
        self._guard(lambda: self._open(name, rrd, live), "could not start the Rerun recording")

    def _open(self, name: str, rrd: Path | None, live: str | None) -> None:
        import rerun as rr

        from noisebo.view.blueprint import blueprint

        self.rr = rr
        self.stream = rr.RecordingStream("noisebo", recording_id=name, send_properties=False)
        sinks: list[LogSinkLike] = []
        if rrd is not None:
            Path(rrd).parent.mkdir(parents=True, exist_ok=True)
            sinks.append(rr.FileSink(str(rrd)))
        if live == "spawn":
            live = DEFAULT_LIVE if self._spawn_viewer() else None
        if live is not None:
            if reachable(live):
                sinks.append(rr.GrpcSink(live))
            else:
                self.warn(f"noisebo: no Rerun viewer answers at {live}; recording to file only")
        if not sinks:
            self.enabled = False
            return
        self.stream.set_sinks(*sinks, default_blueprint=blueprint(self.config))

    def _spawn_viewer(self) -> bool:
        """Start a local viewer (the one installed beside this Python first); False if none starts."""
        bin_dir = str(Path(sys.executable).parent)
        if bin_dir not in os.environ.get("PATH", "").split(os.pathsep):
            os.environ["PATH"] = bin_dir + os.pathsep + os.environ.get("PATH", "")
        try:
            self._recording.spawn(connect=False, hide_welcome_screen=True)
        except Exception as error:  # noqa: BLE001 - no viewer: record to the file only
            self.warn(f"noisebo: could not start a Rerun viewer ({str(error).splitlines()[0]}); recording to file only")
            return False
        for _ in range(20):  # the viewer takes a moment to listen
            if reachable(DEFAULT_LIVE, 0.25):
                return True
            time.sleep(0.25)
        return True

    @property
    def _recording(self) -> RecordingStream:
        """The stream ``_open`` made: what logs to it runs only once it has."""
        assert self.stream is not None
        return self.stream

    def _guard(self, action: Callable[[], None], what: str) -> None:
        if not self.enabled:
            return
        try:
            action()
        except Exception as error:  # noqa: BLE001 - visualisation must never stop a campaign
            self.enabled = False
            self.warn(f"noisebo: {what} ({type(error).__name__}: {error}); visualisation is off for this campaign")

    def fit_ranges(self, frames: list[Frame]) -> None:
        """Size the plot boxes for all of ``frames`` at once (a replay), so they do not rescale
        from frame to frame as they do while a campaign runs."""
        for frame in frames:
            self._ranges(frame)

    def log(self, frame: Frame, spectrum: np.ndarray | None = None, fit: dict | None = None) -> None:
        """Log one frame; ``spectrum`` (3, N) and its ``fit`` (amplitude, resonance_hz, q,
        sign) for PFM's latest sweep."""
        self._guard(lambda: self._log(frame, spectrum, fit), "Rerun logging failed")

    def close(self) -> None:
        stream = self.stream
        if stream is None:
            return

        def finish() -> None:
            stream.flush(timeout_sec=2.0)
            stream.disconnect()

        self._guard(finish, "could not finish the Rerun recording")

    # -- drawing -------------------------------------------------------------------------------

    def _ranges(self, frame: Frame) -> tuple[Box, Box]:
        s = self.config.space
        values = [frame.points["value"]]
        if frame.f is not None:
            values += [frame.f.mean - 2 * frame.f.sd, frame.f.mean + 2 * frame.f.sd]
        if self.truth is not None:
            values.append(self.truth)
        self._f_range = _grow(self._f_range, np.concatenate([np.ravel(v) for v in values]))
        noise = [frame.points["shot_std"][frame.points["noise_measured"]]]
        if frame.noise is not None:
            noise += [frame.noise.mean + 2 * frame.noise.sd]
        self._noise_range = _grow(self._noise_range, np.concatenate([np.ravel(v) for v in noise] + [[0.0]]))
        f_box = Box((s.lows[0], s.highs[0]), self._f_range)
        return f_box, Box((s.t_min, s.t_max), self._noise_range, floor=0.0)  # a standard deviation: never below 0

    def _log(self, frame: Frame, spectrum, fit) -> None:
        rr, st = self.rr, self._recording
        st.set_time("step", sequence=frame.step)
        if self.wall_clock:
            st.set_time("wall", timestamp=time.time())
        f_box, n_box = self._ranges(frame)
        if self.config.space.dimensions == 1:
            self._log_points_on_map(frame)
            self._log_in_flight("acquisition/in_flight", frame, lambda x, t: self._image_box()(x, t))
            if frame.acq_map is not None:
                st.log("acquisition/map", rr.Image(acquisition_image(frame.acq_map)))
                axis = self.config.space.axes[0]
                x_label = self._described.axis_label(axis.name, axis.units)
                self._log_axes("acquisition/axes", self._image_box(), x_label, "t (s)")
            self._log_f(frame, f_box)
        elif self.config.space.dimensions == 2:
            self._log_area(frame)
        self._log_noise(frame, n_box)
        for name in TRACES:
            if name in frame.scalars:
                st.log(f"traces/{name}", rr.Scalars([frame.scalars[name]]))
        st.log("log", rr.TextLog(frame.text, level="INFO"))
        p = frame.points
        xs = np.asarray(p["x"], dtype=np.float64).reshape(len(p["t"]), -1)
        coords = (
            {f"x_{a.name}": xs[:, k] for k, a in enumerate(self.config.space.axes)}
            if xs.shape[1] > 1
            else {"x": xs[:, 0]}
        )
        by = {"instrument": [str(name) for name in p["instrument"]]} if _several(p) else {}
        st.log(
            "campaign/points",
            rr.AnyValues(
                **coords, t=p["t"], value=p["value"], noise=p["noise"], from_step=p["frame"].astype(np.int64), **by
            ),
        )
        if spectrum is not None:
            self._log_spectrum(spectrum, fit)

    def _log_area(self, frame: Frame) -> None:
        """Two axes: GP mean and sd over the area (and the truth, and the acquisition's best
        over t) as images, the measured points on each coloured by their t (log scale)."""
        rr, st, s, p = self.rr, self._recording, self.config.space, frame.points
        xy = np.asarray(p["x"], dtype=np.float64).reshape(len(p["t"]), 2)
        pixels = self._area_pixels(xy, p["t"])
        t_colour = colour_image(
            np.log(np.asarray(p["t"], dtype=np.float64))[None, :], "plasma", (np.log(s.t_min), np.log(s.t_max))
        )[0]
        labels = [
            f"{'seed' if k == 0 else f'step {k}'}: x={format_position(x)}, t={t:.3g} s{_on(name)}"
            for k, x, t, name in zip(p["frame"], xy, p["t"], p["instrument"])
        ]
        images = {}
        if frame.f is not None:
            images["f_mean"] = frame.f.mean
            images["f_sd"] = frame.f.sd
        if self.truth is not None and frame.step == 0:
            images["truth"] = self.truth
        if frame.acq_map is not None:
            images["acquisition"] = frame.acq_map
        for name, values in images.items():
            st.log(
                f"area/{name}/image",
                rr.Image(colour_image(as_image(values, self.config)[::-1], "magma" if name == "f_sd" else "viridis")),
            )
        for name in ("f_mean", "f_sd", "truth", "acquisition"):
            self._log_in_flight(f"area/{name}/in_flight", frame, self._area_pixels)
            st.log(
                f"area/{name}/points",
                rr.Points2D(
                    pixels,
                    colors=t_colour,
                    radii=np.where(p["frame"] == frame.step, 2.0, 1.2),
                    labels=labels,
                    show_labels=False,
                ),
            )

    def _log_in_flight(self, path: str, frame: Frame, place: Callable) -> None:
        """The points in flight at the frame's end (several instruments) at ``place(x, t)``: a
        wide, pale disc in their instrument's colour each, labelled; none: cleared."""
        flying = frame.in_flight
        if flying is None or not len(flying["t"]):
            self._recording.log(path, self.rr.Clear(recursive=False))
            return
        names = flying["instrument"]
        colours = (instrument_colours(names, self.config.instrument_names) * 255).astype(np.uint8)
        colours[:, 3] = IN_FLIGHT_ALPHA
        self._recording.log(
            path,
            self.rr.Points2D(
                place(flying["x"], flying["t"]),
                colors=colours,
                radii=4.0,
                labels=[
                    f"in flight: point {i}, t={t:.3g} s{_on(name)}"
                    for i, t, name in zip(flying["index"], flying["t"], names)
                ],
                show_labels=False,
            ),
        )

    def _area_pixels(self, x, t=None) -> np.ndarray:
        """(n, 2) pixel positions on the area's images of n positions (n, 2) (``t`` unused)."""
        s = self.config.space
        n0, n1 = s.points_per_axis
        xy = np.asarray(x, dtype=np.float64).reshape(-1, 2)
        px = (xy[:, 0] - s.lows[0]) / (s.highs[0] - s.lows[0]) * (n0 - 1) + 0.5
        py = (s.highs[1] - xy[:, 1]) / (s.highs[1] - s.lows[1]) * (n1 - 1) + 0.5
        return np.stack([px, py], axis=-1)

    def _image_box(self) -> ImageBox:
        """(x, t) onto the acquisition image's pixels (one per grid point, t upwards)."""
        s = self.config.space
        return ImageBox((s.x_min, s.x_max), (s.t_min, s.t_max), s.n_x, s.n_t)

    def _log_points_on_map(self, frame: Frame) -> None:
        p = frame.points
        on_image = self._image_box()(p["x"], p["t"])
        labels = [
            f"{'seed' if k == 0 else f'step {k}'}: x={x:.4g}, t={t:.3g} s{_on(name)}"
            for k, x, t, name in zip(p["frame"], p["x"], p["t"], p["instrument"])
        ]
        colours = point_colours(p, self.config)
        self._recording.log(
            "acquisition/points",
            self.rr.Points2D(
                on_image,
                colors=colours,
                radii=np.where(p["frame"] == frame.step, 2.5, 1.5),
                labels=labels,
                show_labels=False,
            ),
        )

    def _log_axes(self, path: str, box: Box, u_label: str, v_label: str) -> None:
        """Axes for a plot box (Rerun's 2D views draw none): the left and bottom lines, ticks at
        round values with their numbers, and each axis's name and units."""
        rr, st = self.rr, self._recording
        u_ticks = ticks(min(box.u0, box.u1), max(box.u0, box.u1))
        v_ticks = ticks(box.v0, box.v1)
        tick = 4.0 * box.width / BOX_W  # in the box's units: the same share of its width
        lines = [np.array([[0.0, 0.0], [0.0, box.height], [box.width, box.height]])]
        lines += [box([u, u], [box.v0, box.v0]) + [[0.0, 0.0], [0.0, tick]] for u in u_ticks]
        lines += [box([box.u0, box.u0], [v, v]) + [[0.0, 0.0], [-tick, 0.0]] for v in v_ticks]
        st.log(f"{path}/lines", rr.LineStrips2D(lines, colors=[(90, 90, 90)], radii=0.3 * box.width / BOX_W))
        u_at = box(u_ticks, np.full(u_ticks.shape, box.v0)) + [0.0, 3 * tick]
        v_at = box(np.full(v_ticks.shape, box.u0), v_ticks) - [4 * tick, 0.0]
        st.log(
            f"{path}/ticks",
            rr.Points2D(
                np.concatenate([u_at, v_at]),
                radii=0.01,
                show_labels=True,
                labels=[f"{v:g}" for v in u_ticks] + [f"{v:.3g}" for v in v_ticks],
                colors=[(90, 90, 90)],
            ),
        )
        st.log(
            f"{path}/names",
            rr.Points2D(
                [[box.width / 2, box.height + 9 * tick], [-14 * tick, box.height / 2]],
                radii=0.01,
                show_labels=True,
                labels=[u_label, v_label],
                colors=[(40, 40, 40)],
            ),
        )

    def _log_curve(self, path: str, box: Box, curve: Curve, colour, band: bool = True) -> None:
        rr, st = self.rr, self._recording
        st.log(f"{path}/mean", rr.LineStrips2D([box(curve.grid, curve.mean)], colors=[colour], radii=0.6))
        if band:
            lowest = np.maximum(curve.mean - 2 * curve.sd, box.v0)  # a noise band stops at 0
            upper, lower = box(curve.grid, curve.mean + 2 * curve.sd), box(curve.grid, lowest)
            st.log(f"{path}/band", rr.LineStrips2D([upper, lower], colors=[colour], radii=0.25))

    def _log_f(self, frame: Frame, box: Box) -> None:
        rr, st, s, p = self.rr, self._recording, self.config.space, frame.points
        if self.truth is not None:
            grid = np.linspace(s.x_min, s.x_max, self.truth.size)
            st.log("f/truth", rr.LineStrips2D([box(grid, self.truth)], colors=[(40, 40, 40)], radii=0.4))
        if frame.f is not None:
            self._log_curve("f", box, frame.f, (31, 119, 180))
        st.log(
            "f/points",
            rr.Points2D(
                box(p["x"], p["value"]),
                colors=point_colours(p, self.config),
                radii=2.0,
                labels=[
                    f"f={v:.4g} +- {n / np.sqrt(k):.2g}{_on(name)}"
                    for v, n, k, name in zip(p["value"], p["noise"], p["n_shots"], p["instrument"])
                ],
                show_labels=False,
            ),
        )
        axis = s.axes[0]
        self._log_axes("f/axes", box, self._described.axis_label(axis.name, axis.units), self._described.value_label)

    def _log_noise(self, frame: Frame, box: Box) -> None:
        rr, st, s, p = self.rr, self._recording, self.config.space, frame.points
        if self.noise_law is not None:
            grid = np.linspace(s.t_min, s.t_max, 200)
            st.log("noise/law", rr.LineStrips2D([box(grid, self.noise_law(grid))], colors=[(40, 40, 40)], radii=0.4))
        measured = p["noise_measured"]
        st.log(
            "noise/points",
            rr.Points2D(
                box(p["t"][measured], p["shot_std"][measured]),
                radii=2.0,
                colors=point_colours(p, self.config, measured),
            ),
        )
        units = f" ({self._described.value_units})" if self._described.value_units else ""
        self._log_axes("noise/axes", box, "t (s)", f"single-shot noise sd{units}")
        if frame.noise is None:
            return
        self._log_curve("noise", box, frame.noise, (214, 39, 40), band=bool(np.any(frame.noise.sd > 0)))
        assert frame.reward is not None  # drawn from the noise model, so there with it
        reward_box = Box((s.t_min, s.t_max), (0.0, 1.0))
        st.log(
            "reward/curve",
            rr.LineStrips2D([reward_box(frame.reward.grid, frame.reward.mean)], colors=[(44, 160, 44)], radii=0.6),
        )
        st.log(
            "reward/t_opt",
            rr.LineStrips2D(
                [reward_box([frame.t_opt, frame.t_opt], [0.0, 1.0])],
                colors=[(0, 0, 0)],
                radii=0.4,
                labels=[f"t_opt = {frame.t_opt:.4g} s"],
                show_labels=True,
            ),
        )

    def _log_spectrum(self, spectrum: np.ndarray, fit: dict | None) -> None:
        from noisebo.sho import sho_amplitude

        rr, st = self.rr, self._recording
        freq, amp = np.asarray(spectrum[0], dtype=np.float64), np.asarray(spectrum[1], dtype=np.float64)
        box = Box((freq[0], freq[-1]), (min(0.0, amp.min()), amp.max()))
        st.log("spectrum/data", rr.Points2D(box(freq, amp), radii=0.4, colors=[(120, 120, 120)]))
        if fit is not None and np.isfinite(fit.get("amplitude", np.nan)):
            model = sho_amplitude(freq, fit["amplitude"], fit["resonance_hz"], fit["q"])
            st.log(
                "spectrum/fit",
                rr.LineStrips2D(
                    [box(freq, model)],
                    colors=[(214, 39, 40)],
                    radii=0.6,
                    labels=[
                        f"SHO fit: r={fit['amplitude']:.3g} pm, "
                        f"f0={fit['resonance_hz'] / 1e3:.2f} kHz, Q={fit['q']:.0f}"
                    ],
                    show_labels=True,
                ),
            )
        else:
            st.log("spectrum/fit", rr.Clear(recursive=False))


def _grow(current: tuple[float, float] | None, values: np.ndarray) -> tuple[float, float]:
    values = values[np.isfinite(values)]
    if values.size == 0:
        return current or (0.0, 1.0)
    lo, hi = float(values.min()), float(values.max())
    return (lo, hi) if current is None else (min(current[0], lo), max(current[1], hi))


def _several(points: dict) -> bool:
    """Whether the points were measured by several named instruments."""
    return any(str(name) for name in points["instrument"])


def _on(name) -> str:
    """ " on NAME" for a point of one of several instruments, nothing otherwise."""
    return f" on {name}" if str(name) else ""
