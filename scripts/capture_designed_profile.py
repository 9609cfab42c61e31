"""A designed motion profile captured against the rig simulators, end to end.

Designs a profile (``mitsweep design-sweep``), serves the simulated devices on ptys
(``python -m mitsweep.rig.simulator arduino|zaber``), captures with it
(``mitsweep capture SETUP --motion PROFILE.json``: the Arduino's step-rate table, then a
Zaber stage's stored stream with the Arduino firing the shutter), and prints planned
against measured: the exposure, the shutter window and the motion, against the plan
(the record's ``measured.profile``) and against the designed profile itself.

The setup's rig is used as it is, except ``--acceleration`` / ``--max-velocity`` (the
design is made for the rig it runs on: it respects ``rig.acceleration``), and for the
Zaber capture the stage's microsteps (0.047625 µm, the X-LSM family's) with the soft
limits held inside the simulated stage's 25 mm travel.

Usage::

    python scripts/capture_designed_profile.py OUT_DIR [--setup scenes/sphere.toml]
        [--lux 2] [--acceleration A] [--planes 64] [--rays 65536] [--profile FILE.json]
        [--stages arduino zaber]

Writes ``OUT_DIR/profile.json`` (unless ``--profile``), the setups, one capture record per
stage and ``comparison.json``.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
#: Zaber X-LSM microsteps per mm (0.047625 µm each).
ZABER_STEPS_PER_MM = 1 / 0.047625e-3
#: The simulated Zaber stage's travel (``ZaberModel``'s default ``limit.max``), microsteps.
ZABER_SIM_MAX_STEPS = 25 * 20997


def _cli(args: list[str], *, timeout: float = 900) -> tuple[str, float]:
    """``mitsweep ARGS`` in a child process: its stdout and wall time; exits on failure."""
    cmd = [sys.executable, "-c", "import sys; from mitsweep.cli.main import main; "
           "sys.exit(main(sys.argv[1:]))", *args]
    print("$ mitsweep", " ".join(args), file=sys.stderr, flush=True)
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, timeout=timeout)
    if proc.returncode != 0:
        sys.stderr.write(proc.stderr[-4000:])
        raise SystemExit(f"mitsweep {args[0]} failed (exit {proc.returncode})")
    return proc.stdout, time.perf_counter() - t0


@contextlib.contextmanager
def simulator(device: str):
    """Serve a simulated ``device`` on a pty in a child process; yields its port."""
    proc = subprocess.Popen([sys.executable, "-m", "mitsweep.rig.simulator", device],
                            cwd=ROOT, stdout=subprocess.PIPE, text=True)
    try:
        port = proc.stdout.readline().strip()
        if not port:
            raise SystemExit(f"the {device} simulator printed no port")
        yield port
    finally:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()


def write_setups(src: Path, out: Path, *, acceleration: float | None,
                 max_velocity: float | None) -> dict[str, Path]:
    """The setup for the Arduino capture (the rig overridden as asked) and for the Zaber
    capture (the same, in Zaber microsteps, soft limits inside the simulated travel)."""
    from mitsweep.config import load_setup, setup_to_toml

    s = load_setup(src)
    rig = s.rig
    if acceleration is not None:
        rig = dataclasses.replace(rig, acceleration=float(acceleration))
    if max_velocity is not None:
        rig = dataclasses.replace(rig, max_velocity=float(max_velocity))
    zaber_max = ZABER_SIM_MAX_STEPS / ZABER_STEPS_PER_MM
    rigs = {"arduino": rig,
            "zaber": dataclasses.replace(rig, steps_per_mm=ZABER_STEPS_PER_MM,
                                         soft_limit_max=min(rig.soft_limit_max,
                                                            np.floor(zaber_max * 100) / 100))}
    paths = {}
    for stage, r in rigs.items():
        p = out / f"setup_{stage}.toml"
        p.write_text(setup_to_toml(dataclasses.replace(s, rig=r),
                                   header=f"{src.name}, rig for the {stage} simulator: "
                                          f"scripts/capture_designed_profile.py"),
                     encoding="utf-8")
        paths[stage] = p
    return paths


def compare(record_path: Path, profile_path: Path) -> dict:
    """Planned against measured in one capture record: exposure, shutter window, motion
    (against the plan's table and against the designed profile itself)."""
    from mitsweep.optics.motion_file import load_motion_file
    from mitsweep.rig import load_capture_record, measured_motion

    rec = load_capture_record(record_path)
    plan, m = rec["plan"], rec["measured"]
    e, cmp = m["exposure"], m["profile"]
    mf = load_motion_file(profile_path)
    t, s = measured_motion(record_path)
    ideal = mf.profile.sensor_distance(np.clip(t / plan["exposure_s"], 0.0, 1.0))
    vel = lambda x, sel: np.polyfit(t[sel], x[sel], 1)[0]  # noqa: E731 - sensor mm/s
    first, last = t <= 0.2 * t[-1], t >= 0.8 * t[-1]
    return {
        "complete": rec["complete"], "stage": plan["stage"],
        "exposure": {"profile_s": mf.exposure_s, "planned_s": e["planned_exposure_s"],
                     "measured_s": e["measured_exposure_s"],
                     "timing_uncertainty_s": e["timing_uncertainty_s"]},
        "shutter_window": {
            "planned_open_mm": plan["open_mm"], "measured_open_mm": e["open_position_mm"],
            "planned_close_mm": plan["close_mm"], "measured_close_mm": e["close_position_mm"],
            "profile_sensor_mm": [float(mf.profile.positions[0]),
                                  float(mf.profile.positions[-1])],
            "measured_sensor_mm": [e["open_sensor_distance_mm"],
                                   e["close_sensor_distance_mm"]]},
        "motion": {
            "samples": len(cmp["time_s"]), "source": m["motion"]["source"],
            "segments": plan["profile"]["segments"],
            "max_deviation_from_plan_steps": cmp["max_deviation_steps"],
            "allowed_steps": cmp["tolerance_steps"],
            "table_deviation_from_profile_steps": cmp["table_max_deviation_steps"],
            "steps_per_mm": plan["steps_per_mm"],
            "max_deviation_from_profile_um": float(1e3 * np.max(np.abs(s - ideal))),
            "velocity_first_last_fifth_mm_s": {"profile": [vel(ideal, first), vel(ideal, last)],
                                               "measured": [vel(s, first), vel(s, last)]}},
    }


def summary(c: dict) -> str:
    e, w, mo = c["exposure"], c["shutter_window"], c["motion"]
    vp, vm = (mo["velocity_first_last_fifth_mm_s"][k] for k in ("profile", "measured"))
    return "\n".join([
        f"{c['stage']}: {'complete' if c['complete'] else 'INCOMPLETE'}",
        f"  exposure       profile {e['profile_s']:.6f} s, planned {e['planned_s']:.6f} s, "
        f"measured {e['measured_s']:.6f} s (± {e['timing_uncertainty_s'] * 1e6:.1f} µs)",
        f"  shutter window planned {w['planned_open_mm']:.6f} -> {w['planned_close_mm']:.6f} mm, "
        f"measured {w['measured_open_mm']:.6f} -> {w['measured_close_mm']:.6f} mm "
        f"(sensor {w['measured_sensor_mm'][0]:.4f} -> {w['measured_sensor_mm'][1]:.4f}, "
        f"profile {w['profile_sensor_mm'][0]:.4f} -> {w['profile_sensor_mm'][1]:.4f} mm)",
        f"  motion         {mo['segments']} segments; at {mo['samples']} samples measured within "
        f"{mo['max_deviation_from_plan_steps']:.2f} steps of the plan (allowed "
        f"{mo['allowed_steps']:.2f}), within {mo['max_deviation_from_profile_um']:.2f} µm of "
        f"the profile (table {mo['table_deviation_from_profile_steps']:.3f} steps off it)",
        f"  speed          first/last fifth of the exposure (line fits): profile "
        f"{abs(vp[0]):.4f}/{abs(vp[1]):.4f} mm/s, measured {abs(vm[0]):.4f}/{abs(vm[1]):.4f} mm/s",
    ])


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("out", type=Path)
    p.add_argument("--setup", type=Path, default=ROOT / "scenes" / "sphere.toml")
    p.add_argument("--lux", default="2")
    p.add_argument("--acceleration", type=float, help="rig.acceleration, mm/s² (default: "
                                                      "the setup's)")
    p.add_argument("--max-velocity", type=float, help="rig.max_velocity, mm/s (default: "
                                                      "the setup's)")
    p.add_argument("--planes", default="64")
    p.add_argument("--rays", default="65536")
    p.add_argument("--profile", type=Path, help="capture this motion-profile file instead "
                                                "of designing one")
    p.add_argument("--stages", nargs="+", choices=("arduino", "zaber"),
                   default=["arduino", "zaber"])
    a = p.parse_args(argv)
    for name in ("acceleration", "max_velocity"):
        v = getattr(a, name)
        if v is not None and not (np.isfinite(v) and v > 0):
            p.error(f"--{name.replace('_', '-')}: must be a finite number > 0, got {v}")
    a.out.mkdir(parents=True, exist_ok=True)
    setups = write_setups(a.setup, a.out, acceleration=a.acceleration,
                          max_velocity=a.max_velocity)
    result: dict = {"setup": str(a.setup), "rig_overrides": {
        "acceleration": a.acceleration, "max_velocity": a.max_velocity}}
    if a.profile is None:
        profile = a.out / "profile.json"
        stdout, secs = _cli(["design-sweep", str(setups["arduino"]), "--lux", a.lux,
                             "--planes", a.planes, "--rays", a.rays, "--out", str(profile),
                             "--json"])
        rep = json.loads(stdout)
        result["design"] = {k: rep[k] for k in ("linear_worst_psnr_db",
                                                "optimized_worst_psnr_db", "velocity_mm_s",
                                                "max_acceleration_mm_s2", "stage_limits",
                                                "exposure_s")}
        result["design"]["seconds"] = secs
        result["design"]["lux"] = float(a.lux)
    else:
        profile = a.profile
    result["profile"] = str(profile)
    texts = []
    for stage in a.stages:
        rec = a.out / f"capture_{stage}.json"
        with contextlib.ExitStack() as stack:
            board = stack.enter_context(simulator("arduino"))
            args = ["capture", str(setups[stage]), "--port", board, "--motion", str(profile),
                    "--out", str(rec), "--force", "--json"]
            if stage == "zaber":
                args[4:4] = ["--stage", f"zaber:{stack.enter_context(simulator('zaber'))}"]
            _, secs = _cli(args, timeout=300)
        c = compare(rec, profile)
        c["capture_s"] = secs
        result[stage] = c
        texts.append(summary(c))
    (a.out / "comparison.json").write_text(json.dumps(result, indent=1), encoding="utf-8")
    if "design" in result:
        d = result["design"]
        print(f"design: {a.setup.name} at {d['lux']:g} lux, velocity "
              f"{d['velocity_mm_s'][0]:.4f}..{d['velocity_mm_s'][1]:.4f} mm/s, peak "
              f"acceleration {d['max_acceleration_mm_s2']:.4g} mm/s² (rig "
              f"{d['stage_limits']['acceleration_mm_s2']:g}), exposure {d['exposure_s']:.6f} s")
    print("\n".join(texts))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
