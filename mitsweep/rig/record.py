"""The capture record: one JSON file per capture, written atomically, never lost.

Layout (``format = "mitsweep-capture-record"``, ``version = 1``)::

    complete        true only when the sweep ran to its end with the shutter cycle seen
    status          "running" | "complete" | "interrupted" | "timeout" | "port lost" |
                    "fault" | "host too slow" | "error"
    error           the reason, one line (null when complete)
    signal          the signal that interrupted the capture ("SIGINT", "SIGTERM",
                    "SIGHUP"), else null; signals_during_safety: those that arrived
                    while the safety path ran (and did not stop it)
    setup           the setup (normalised, as setup_to_dict)
    plan            the CapturePlan (positions, rates, planned exposure, sensor mapping;
                    a motion profile's step-rate table under plan.profile)
    motion          the motion-profile file run (file, exposure_s, provenance), or null
    ports, devices  what was opened and how the devices identified themselves
    marks           host-time milestones (homed, at approach position, sweep started ...)
    commands        every line sent and received: t_s (host monotonic, s since the
                    capture started), device, dir ("tx"/"rx"), text
    events          the Arduino's events (board µs clock, unwrapped)
    stage_samples   Zaber position polls (host t_s, microsteps, ± s: half the poll's
                    round trip), zaber mode only
    clock_map       zaber mode: board µs ↔ host s at the SHUTTER exchange (uncertainty_s:
                    half its round trip); placement_uncertainty_s bounds how far from its
                    planned time the host-timed shutter opened (move sent → SHUTTER reply)
    safety          what the safety path did: device, action, confirms (what the step
                    makes safe), ok (the device confirmed it), reason and detail (why
                    not)
    measured        exposure: open/close times and positions, measured exposure;
                    motion: time_s (from shutter open), position_mm, sensor_distance_mm;
                    profile (a motion-profile capture): the plan's position at those
                    times and the largest deviation (:func:`planned_versus_measured`)
    reference       complete records: the reference geometry of the measured motion
                    (mitsweep.optics.reference.reference_geometry(setup, motion=the
                    tabulated measured profile).as_dict(): reference_sensor_distance_mm,
                    sweep, motion), so a bank traced for this capture uses its grid

``measured.motion`` is a measured motion profile: :func:`measured_motion` returns it as
``(times_s, sensor_distance_mm)`` arrays, ready for
``mitsweep.optics.motion.MotionProfile.tabulated(times, positions)``.
"""

from __future__ import annotations

import datetime as _dt
import json
import logging
import platform
from pathlib import Path
from typing import Any
from collections.abc import Iterable, Mapping

import numpy as np

# absolute: tests/test_rig_imports.py admits optics, config and io as relative imports;
from ..deprecation import renamed_keywords

from ..config import Setup
from .errors import RigError
from .plan import CapturePlan
from .transport import CommandLog

__all__ = ["FORMAT", "VERSION", "CaptureRecord", "load_capture_record", "measured_motion"]

logger = logging.getLogger(__name__)

FORMAT = "mitsweep-capture-record"
VERSION = 1


class CaptureRecord:
    """Accumulates a capture as it happens; :meth:`save` writes it (atomically).

    Parameters
    ----------
    setup : mitsweep.config.Setup
        The setup captured.
    plan : CapturePlan
        The resolved plan.
    log : CommandLog
        Every line exchanged with the devices, with timestamps.
    ports : RigPorts, optional
        The ports used (recorded as they were given).
    path : str or Path, optional
        Where :meth:`save` writes the record (none: not written).
    """

    def __init__(self, *, setup: Setup, plan: CapturePlan, log: CommandLog, ports: Any = None,
                 path: str | Path | None = None) -> None:
        self.setup = setup
        self.plan = plan
        self.log = log
        self.ports = ports
        self.path = Path(path) if path is not None else None
        self.status = "running"
        self.complete = False
        self.error: str | None = None
        self.signal: str | None = None
        self.signals_during_safety: list[str] = []
        self.devices: dict[str, str] = {}
        self.homed = False
        self.marks: list[dict] = []
        self.safety_actions: list[dict] = []
        self.board_events: list = []
        self.stage_samples: list[tuple[float, int, float]] = []
        self.clock_map: dict | None = None
        self.motion: dict | None = None        # the motion-profile file run, if any
        self.created_utc = _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds")

    # -- accumulate ---------------------------------------------------------------------
    def mark(self, what: str) -> None:
        """Note a milestone at the log's present time.

        Parameters
        ----------
        what : str
            What happened, e.g. ``"at approach position"``.
        """
        self.marks.append({"t_s": round(self.log.now(), 6), "what": what})

    def safety(self, device: str, action: str, *, ok: bool, confirms: str, detail: str = "",
               reason: str = "") -> None:
        """Record one step of the safety path.

        Parameters
        ----------
        device : str
            ``"arduino"`` or ``"zaber"``.
        action : str
            What was sent, e.g. ``"stop stage"``.
        ok : bool
            Whether the device confirmed it.
        confirms : str
            What the step makes safe, e.g. ``"shutter released"``.
        detail : str
            The error's text, when not confirmed.
        reason : str
            Why not, briefly (``"port lost"``, ``"no reply"``, ...).
        """
        self.safety_actions.append({"t_s": round(self.log.now(), 6), "device": device,
                                    "action": action, "confirms": confirms, "ok": ok,
                                    "reason": reason, "detail": detail})

    def set_board_events(self, events: Iterable[Any]) -> None:
        """Keep the board's events (replacing those kept before).

        Parameters
        ----------
        events : iterable of BoardEvent
            Every event the Arduino sent, in order.
        """
        self.board_events = list(events)

    def set_stage_samples(self, samples: Iterable[tuple[float, int, float]]) -> None:
        """Keep the Zaber stage's position polls (replacing those kept before).

        Parameters
        ----------
        samples : iterable of (float, int, float)
            ``(host time s, microsteps, ± s)`` of each poll.
        """
        self.stage_samples = list(samples)

    def finish(self, *, complete: bool, status: str, error: str | None = None) -> None:
        """Mark the capture finished.

        Parameters
        ----------
        complete : bool
            The sweep ran to its end: the measurement must then be whole (else
            :class:`~mitsweep.rig.errors.RigError`).
        status : str
            The record's status (``"complete"``, ``"interrupted"``, ``"timeout"``, ...).
        error : str, optional
            The reason, one line (None when complete).
        """
        if complete:
            self.measurement(strict=True)   # a complete record has its measurement
        self.complete, self.status, self.error = complete, status, error

    # -- measurement --------------------------------------------------------------------
    def _sweep_events(self):
        evs = self.board_events
        starts = [i for i, e in enumerate(evs) if e.name == "START"]
        if self.plan.stage == "arduino" and starts:
            evs = evs[starts[-1]:]
        if self.plan.stage == "zaber" and self.clock_map is not None:
            # the last SHUTTER's exposure, not one of an abandoned attempt
            evs = [e for e in evs if e.t_us >= self.clock_map["board_t_us"]]
        opens = [e for e in evs if e.name == "OPEN"]
        closes = [e for e in evs if e.name == "CLOSE"]
        return evs, (opens[-1] if opens else None), (closes[-1] if closes else None)

    def measurement(self, *, strict: bool = False) -> dict | None:
        """Measured exposure and motion, or None (``strict``: raise) when the shutter
        cycle was not seen whole.

        Parameters
        ----------
        strict : bool
            Raise :class:`~mitsweep.rig.errors.RigError` instead of returning None.

        Returns
        -------
        dict or None
            ``exposure``, ``motion`` and, for a motion profile, ``profile``: the record's
            ``measured`` (module docstring).
        """
        plan = self.plan
        evs, ev_open, ev_close = self._sweep_events()
        if ev_open is None or ev_close is None or ev_close.t_us <= ev_open.t_us:
            if strict:
                raise RigError("capture: the shutter's OPEN/CLOSE events were not both seen")
            return None
        exposure = (ev_close.t_us - ev_open.t_us) * 1e-6
        if plan.stage == "arduino":
            pts = [(ev_open.t_us, ev_open.position)]
            pts += [(e.t_us, e.position) for e in evs
                    if e.name == "POS" and ev_open.t_us < e.t_us < ev_close.t_us]
            pts.append((ev_close.t_us, ev_close.position))
            t = np.array([(p[0] - ev_open.t_us) * 1e-6 for p in pts])
            x = np.array([p[1] for p in pts], dtype=float) / plan.steps_per_mm
            source = "arduino events (board micros clock)"
            uncertainty = 1e-6
            sample_uncertainty = 2e-6           # two micros() stamps
        else:
            if self.clock_map is None or len(self.stage_samples) < 2:
                if strict:
                    raise RigError("capture: no stage position samples to place the exposure")
                return None
            cm = self.clock_map
            to_host = lambda t_us: cm["host_t_s"] + (t_us - cm["board_t_us"]) * 1e-6
            h_open, h_close = to_host(ev_open.t_us), to_host(ev_close.t_us)
            st = np.array([s[0] for s in self.stage_samples])
            sx = np.array([s[1] for s in self.stage_samples], dtype=float) / plan.steps_per_mm
            inside = (st > h_open) & (st < h_close)
            t = np.concatenate([[h_open], st[inside], [h_close]]) - h_open
            x = np.concatenate([[np.interp(h_open, st, sx)], sx[inside],
                                [np.interp(h_close, st, sx)]])
            source = "zaber position polls (host clock), interpolated at the shutter events"
            # the clock mapping's, plus the larger of the two polls each interpolation
            # uses (a poll's time is known to half its round trip)
            su = np.array([s[2] for s in self.stage_samples])
            near = lambda h: su[np.clip(np.searchsorted(st, h) + np.array([-1, 0]),
                                        0, len(st) - 1)].max()
            uncertainty = cm["uncertainty_s"] + max(near(h_open), near(h_close))
            # a profile sample against the plan: its poll's time, the clock mapping, and
            # where the host-timed shutter opened relative to the stage's start
            sample_uncertainty = (cm["uncertainty_s"] + cm.get("placement_uncertainty_s", 0.0)
                                  + max(near(h_open), near(h_close),
                                        float(su[inside].max()) if inside.any() else 0.0))
        s = plan.sensor_distance(x)
        out = {
            "exposure": {
                "measured_exposure_s": exposure,
                "planned_exposure_s": plan.planned_exposure_s,
                "optical_exposure_s": plan.exposure_s,
                "open_board_t_us": ev_open.t_us, "close_board_t_us": ev_close.t_us,
                "open_position_mm": float(x[0]), "close_position_mm": float(x[-1]),
                "open_sensor_distance_mm": float(s[0]),
                "close_sensor_distance_mm": float(s[-1]),
                "timing_uncertainty_s": uncertainty,
            },
            "motion": {"time_s": t.tolist(), "position_mm": x.tolist(),
                       "sensor_distance_mm": s.tolist(), "source": source},
        }
        if plan.profile is not None:
            out["profile"] = planned_versus_measured(plan, t, x, sample_uncertainty)
        return out

    # -- output -------------------------------------------------------------------------
    def as_dict(self) -> dict:
        from .. import __version__
        from ..config import setup_to_dict

        ports = None
        if self.ports is not None:
            ports = {"arduino": self.ports.arduino, "zaber": self.ports.zaber,
                     "checksums": self.ports.checksums, "watchdog_s": self.ports.watchdog_s}
        measured = self.measurement()
        return {
            "format": FORMAT, "version": VERSION,
            "complete": self.complete, "status": self.status, "error": self.error,
            "signal": self.signal, "signals_during_safety": list(self.signals_during_safety),
            "created_utc": self.created_utc, "mitsweep_version": __version__,
            "host": platform.node(),
            "setup": setup_to_dict(self.setup), "plan": self.plan.as_dict(),
            "motion": self.motion,
            "ports": ports, "devices": dict(self.devices), "homed": self.homed,
            "marks": list(self.marks),
            "commands": self.log.as_list(),
            "events": [e.as_dict() for e in self.board_events],
            "stage_samples": [[round(t, 6), int(p), round(u, 6)]
                              for t, p, u in self.stage_samples],
            "clock_map": self.clock_map,
            "safety": list(self.safety_actions),
            "measured": measured,
            "reference": self.reference(measured) if self.complete else None,
        }

    def reference(self, measured: dict | None = None) -> dict | None:
        """The reference geometry of the measured motion
        (:func:`mitsweep.optics.reference.reference_geometry` with the tabulated measured
        profile), as a dict, so that a PSF bank traced for this capture uses the same
        grid (reference sensor distance: the measured span's midpoint); None without a
        measurement.

        Parameters
        ----------
        measured : dict, optional
            The measurement (:meth:`measurement`), when already computed.
        """
        if measured is None:
            measured = self.measurement()
        if measured is None:
            return None
        from ..optics.motion import MotionProfile
        from ..optics.reference import reference_geometry

        m = measured["motion"]
        motion = MotionProfile.tabulated(m["time_s"], m["sensor_distance_mm"])
        return reference_geometry(self.setup, motion=motion).as_dict()

    def save(self) -> Path | None:
        """Write the record atomically to :attr:`path` (no-op without a path)."""
        if self.path is None:
            return None
        from ..io.atomic import write_text_atomic

        write_text_atomic(self.path, json.dumps(_jsonable(self.as_dict()), indent=1) + "\n")
        return self.path


@renamed_keywords(position_mm="position")
def planned_versus_measured(plan, time_s, position, timing_uncertainty_s: float) -> dict:
    """A profile capture's measured motion against its plan, at the measured times.

    ``planned_position_mm``: the step-rate table's commanded position (its travel from
    the open step, the stepper at its floor); ``profile_sensor_distance_mm``: the motion
    profile itself (unquantised). ``max_deviation_steps`` is the largest |measured −
    planned|; ``tolerance_steps`` what the measurement allows: one step (the stepper's
    floor) plus the table's peak rate over the timing uncertainty of a sample (the
    simulator's 1 µs stamps, or the Zaber polls' half round trip and the host-timed
    shutter's placement).

    Parameters
    ----------
    plan : CapturePlan
        A motion profile's plan (``plan.profile`` set).
    time_s : array_like
        Measured times from the shutter's opening, s.
    position : array_like
        Measured stage positions at those times, mm.
    timing_uncertainty_s : float
        How far a sample's time may be off, s.

    Returns
    -------
    dict
        The record's ``measured.profile`` (JSON-ready lists and numbers).
    """
    table = plan.profile
    spm = plan.steps_per_mm
    t = np.asarray(time_s, dtype=float)
    travel = np.floor(table.travel_at(t) + 1e-9)
    planned = (plan.open_steps + plan.direction * travel) / spm
    ideal = (plan.open_steps + plan.direction * np.interp(t, table.knot_times_s,
                                                          table.knot_travel_steps)) / spm
    dev = np.abs(np.asarray(position, dtype=float) - planned) * spm
    peak_rate = max(k / d for k, d in zip(table.steps, table.durations_s))
    return {"time_s": t.tolist(), "planned_position_mm": planned.tolist(),
            "planned_sensor_distance_mm": plan.sensor_distance(planned).tolist(),
            "profile_sensor_distance_mm": plan.sensor_distance(ideal).tolist(),
            "max_deviation_steps": float(dev.max()),
            "tolerance_steps": 1.0 + peak_rate * timing_uncertainty_s,
            "table_max_deviation_steps": table.max_deviation_steps}


def _jsonable(o):
    if isinstance(o, float):
        return o if np.isfinite(o) else None
    if isinstance(o, dict):
        return {k: _jsonable(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_jsonable(v) for v in o]
    if isinstance(o, np.generic):
        return o.item()
    return o


def load_capture_record(path: str | Path) -> dict:
    """Read a capture record; :class:`ValueError` if it is not one this version reads.

    Parameters
    ----------
    path : str or Path
        A capture record written by ``mitsweep capture`` (JSON).
    """
    p = Path(path)
    try:
        data = json.loads(p.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise FileNotFoundError(f"{p}: no such capture record") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"{p}: not a JSON capture record ({exc})") from None
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise ValueError(f"{p}: not a {FORMAT} file")
    if data.get("version") != VERSION:
        raise ValueError(f"{p}: capture record version {data.get('version')!r}, this "
                         f"mitsweep reads version {VERSION}")
    return data


def measured_motion(record: Mapping[str, Any] | str | Path, *, require_complete: bool = True
                   ) -> tuple[np.ndarray, np.ndarray]:
    """The measured motion profile of a capture: ``(times_s, sensor_distance_mm)``.

    Parameters
    ----------
    record : dict or path
        A record (as loaded by :func:`load_capture_record`) or its path.
    require_complete : bool
        Refuse a record marked incomplete (default).

    Returns
    -------
    times_s : (n,) ndarray
        Seconds since the shutter opened; ``times_s[-1]`` is the measured exposure.
    sensor_distance_mm : (n,) ndarray
        Lens-to-sensor distance at those times, mm.

    Examples
    --------
    >>> from mitsweep.optics.motion import MotionProfile        # doctest: +SKIP
    >>> profile = MotionProfile.tabulated(*measured_motion("capture.json"))  # doctest: +SKIP
    """
    if not isinstance(record, Mapping):
        record = load_capture_record(record)
    if require_complete and not record.get("complete"):
        raise ValueError(f"capture record marked incomplete (status {record.get('status')!r}: "
                         f"{record.get('error')}); pass require_complete=False to use it")
    measured = record.get("measured")
    if not measured:
        raise ValueError("capture record holds no measured exposure (the shutter cycle "
                         "was not seen whole)")
    m = measured["motion"]
    return np.asarray(m["time_s"], dtype=float), np.asarray(m["sensor_distance_mm"], dtype=float)
