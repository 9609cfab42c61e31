"""The measured tables of the docs, tied to the commands that produce them.

Every Markdown table of ``docs/**/*.md`` whose cells hold a number carries a marker, an
HTML comment on the lines just above it (blank lines between are allowed)::

    <!-- figures: NAME; tolerance: printed -->

``figures: NAME``
    the table is produced by the figure ``NAME`` of :data:`FIGURES`: its command(s) are
    run and each documented number is checked against the value the command prints.
``figures: timing``
    a table of machine-dependent timings: not asserted, but the paragraph above the
    table must name the command that measured it (in backticks) and the machine.
``figures: generated (TEST)``
    the table is written by code and compared with it by TEST (e.g. the setup keys).
``figures: not checked (REASON)``
    the numbers are not re-run (the paper's own, a study of hours, a photograph);
    REASON says why, and the report of ``tests/test_doc_figures.py`` lists it.

``tolerance`` (checked tables only): ``printed`` (the default: the documented number
is the command's value rounded to the digits shown, i.e. within half a unit of its last
digit), ``N%`` (relative) or ``±X`` (absolute); several, separated by ``,``, are added.

A figure (:class:`Figure`) says which command the page cites (the test checks that the
text above the table names it), the commands run (as a reader would type them, from the
repository's root) and a function that turns their outputs into the table's rows: one
list per row, one entry per cell: ``None`` for a cell that is not checked (a label, a
number quoted from the paper, a timing), else the list of numbers the cell must show, in
order (``None`` in that list: a number not compared, a timing beside a checked one).
Numbers are read from a cell as written (``−`` is a minus sign, ``–`` a range's dash,
``12,403`` one number; ``±`` and ``°`` are dropped).

A figure whose commands take far longer than the tests may (a forty-minute benchmark)
is checked against their recorded output, committed beside the page and rewritten by
the command (``Figure.recorded``, e.g. ``docs/benchmarks.json``); the page says so.

``python tests/doc_figures.py`` prints each table's status; the test does too, with ``-s``.
"""

from __future__ import annotations

import functools
import json
import math
import re
import subprocess
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
_NUMBER = re.compile(r"(?<![A-Za-z_\d.])[-+]?(?:\d{1,3}(?:,\d{3})+(?!\d)|\d+\.\d*|\.\d+|\d+)"
                     r"(?:[eE][-+]?\d+)?")
_MARKER = re.compile(r"<!--\s*figures:(?P<body>.*?)-->", re.S)
#: A machine, as a timing table's paragraph must name it.
MACHINE = re.compile(r"\b(core|cores|CPU|GPU|H200|VM|machine)\b", re.I)

Rows = list[list[list[float | None] | None]]


@dataclass(frozen=True)
class Figure:
    """How one documented table is reproduced.

    Attributes
    ----------
    cites : str
        The command as the page names it next to the table (checked to be there).
    commands : tuple of str
        The shell commands run, from the repository's root; their stdout are passed, in
        order, to ``rows``.
    rows : callable
        ``rows(outputs) -> Rows``: the table's expected numbers (see the module doc).
    slow : bool
        True when the commands take more than about 10 s together (run with ``-m slow``).
    recorded : str, optional
        For commands far too long for the tests (a benchmark of forty minutes): the file,
        relative to the repository's root, that holds their output as committed, written
        by the command (e.g. ``docs/benchmarks.json``). The table is checked against it;
        rerunning the command rewrites it, and then the table must follow.
    timings : bool
        Some cells are timings (not compared): the paragraph above must name the machine.
    """
    cites: str
    commands: tuple[str, ...]
    rows: Callable[[list[str]], Rows]
    slow: bool = False
    recorded: str | None = None
    timings: bool = False

    def outputs(self) -> list[str]:
        """The commands' outputs: run now, or as recorded."""
        if self.recorded is not None:
            return [(ROOT / self.recorded).read_text(encoding="utf-8")]
        return [run(c) for c in self.commands]


@dataclass
class Table:
    """One Markdown table of a page, with its marker."""
    path: Path
    line: int
    header: list[str]
    body: list[list[str]]
    above: str
    marker: dict

    @property
    def where(self) -> str:
        return f"{self.path.relative_to(ROOT).as_posix()}:{self.line}"

    @property
    def kind(self) -> str:
        """``check``, ``timing``, ``generated``, ``not checked`` or ``none``."""
        name = self.marker.get("figures", "")
        for kind in ("timing", "generated", "not checked"):
            if name.startswith(kind):
                return kind
        return "check" if name else "none"

    @property
    def has_numbers(self) -> bool:
        return any(numbers(c) for row in self.body for c in row)


def doc_pages() -> list[Path]:
    """Every Markdown page of docs/, but the build's output and docs/benchmarks.md
    (generated from its JSON by scripts/bench_docs.py, checked by
    tests/test_bench_docs.py)."""
    return [p for p in sorted((ROOT / "docs").rglob("*.md"))
            if "_build" not in p.parts and p.name != "benchmarks.md"]


def _split_row(line: str) -> list[str]:
    cells = re.split(r"(?<!\\)\|", line.strip().strip("|"))
    return [c.strip() for c in cells]


def _marker(lines: list[str], i: int) -> dict:
    """The ``figures:`` marker among the one-line HTML comments (and blank lines) right
    above line ``i``, parsed."""
    k = i - 1
    while k >= 0 and (not lines[k].strip() or (lines[k].lstrip().startswith("<!--")
                                               and lines[k].rstrip().endswith("-->"))):
        m = _MARKER.fullmatch(lines[k].strip())
        if m:
            out: dict = {}
            for part in re.split(r";\s*(?=tolerance\s*:)", m.group("body")):
                key, sep, value = part.partition(":")
                if not out:                     # the first part is the figure itself
                    out["figures"] = part.strip()
                elif sep:
                    out[key.strip().lower()] = value.strip()
            return out
        k -= 1
    return {}


def tables(paths: Sequence[Path] | None = None) -> list[Table]:
    """Every Markdown table of the given pages (default: all of docs/)."""
    found = []
    for path in paths or doc_pages():
        lines = path.read_text(encoding="utf-8").splitlines()
        i = 0
        while i < len(lines):
            if lines[i].startswith("|") and i + 1 < len(lines) \
                    and re.fullmatch(r"\|(\s*:?-{3,}:?\s*\|)+", lines[i + 1].strip()):
                j = i + 2
                while j < len(lines) and lines[j].startswith("|"):
                    j += 1
                found.append(Table(path, i + 1, _split_row(lines[i]),
                                   [_split_row(l) for l in lines[i + 2:j]],
                                   _prose_above(lines, i), _marker(lines, i)))
                i = j
                continue
            i += 1
    return found


def _prose_above(lines: list[str], i: int) -> str:
    """The paragraph above line ``i`` (its marker and blank lines skipped)."""
    k = i - 1
    while k >= 0 and (not lines[k].strip() or lines[k].lstrip().startswith("<!--")
                      or lines[k].rstrip().endswith("-->")):
        k -= 1
    end = k
    while k >= 0 and lines[k].strip() and not lines[k].startswith("|"):
        k -= 1
    return "\n".join(lines[k + 1:end + 1])


def numbers(cell: str) -> list[float]:
    """The numbers a cell shows, as written (see the module doc)."""
    return [float(n) for n in _written(cell)]


def _written(cell: str) -> list[str]:
    """The numbers of a cell as strings (for their printed digits); code spans, images
    and links are not read, nor digits that are part of a name (``F11``, ``fig3``)."""
    text = re.sub(r"`[^`]*`|!?\[[^\]]*\]\([^)]*\)", " ", cell)
    text = text.replace("\u2212", "-").replace("±", " ").replace("°", " ")
    text = re.sub(r"(?<=\d)\s*[–—]\s*(?=[-\d])", " ", text)   # a range's dash
    return [n.replace(",", "") for n in _NUMBER.findall(text)]


def slack(written: str, tolerance: str) -> float:
    """The largest allowed difference for a number ``written`` so, under ``tolerance``."""
    value = float(written)
    allowed = 0.0
    for part in (p.strip() for p in (tolerance or "printed").split(",")):
        if part == "printed":
            mantissa, _, exponent = written.lower().partition("e")
            decimals = len(mantissa.split(".")[1]) if "." in mantissa else 0
            allowed += 0.5 * 10.0 ** (int(exponent or 0) - decimals)
        elif part.endswith("%"):
            allowed += float(part[:-1]) / 100 * abs(value)
        elif part.startswith("±"):
            allowed += float(part[1:])
        else:
            raise ValueError(f"tolerance {part!r}: expected printed, N% or ±X")
    return allowed * (1 + 1e-9)


def compare(table: Table, expected: Rows) -> list[str]:
    """The mismatches between a table's cells and the numbers a figure expects."""
    tolerance = table.marker.get("tolerance", "printed")
    if len(expected) != len(table.body):
        return [f"{table.where}: {len(table.body)} rows documented, {len(expected)} produced"]
    problems = []
    for r, (doc_row, want_row) in enumerate(zip(table.body, expected)):
        if len(want_row) != len(doc_row):
            problems.append(f"row {r + 1}: {len(doc_row)} cells, {len(want_row)} produced")
            continue
        for c, (cell, want) in enumerate(zip(doc_row, want_row)):
            if want is None:
                continue
            shown = _written(cell)
            if len(shown) != len(want):
                problems.append(f"row {r + 1} {table.header[c]!r}: {cell!r} shows "
                                f"{len(shown)} numbers, the command gives {list(want)}")
                continue
            for w, value in zip(shown, want):
                if value is None:       # a timing beside a checked number
                    continue
                if not (abs(float(w) - value) <= slack(w, tolerance)
                        or (math.isinf(value) and math.isinf(float(w)))):
                    problems.append(f"row {r + 1} {table.header[c]!r}: {w} documented, "
                                    f"{value:.6g} computed (tolerance {tolerance})")
    return [f"{table.where}: {p}" for p in problems]


@functools.cache
def run(command: str, timeout: float = 600) -> str:
    """stdout of ``command`` run from the repository's root (cached per test session)."""
    from doc_snippets import environment
    done = subprocess.run(command, shell=True, cwd=ROOT, env=environment(), text=True,
                          capture_output=True, timeout=timeout)
    if done.returncode != 0:
        raise RuntimeError(f"{command!r} exited {done.returncode}: {done.stderr[-2000:]}")
    return done.stdout


def _json(text: str) -> dict:
    return json.loads(text[text.index("{"):text.rindex("}") + 1])


# -- the figures ------------------------------------------------------------------------

_SETUPS = ("sphere", "paraboloid", "paraboloid_tilted")


def _sweep_design_rows(outputs: list[str]) -> Rows:
    """setup | FOV | paper sweep | mitsweep sweep | paper travel | mitsweep travel."""
    rows: Rows = []
    for text in outputs:
        d = _json(text)
        rows.append([None, [d["fov_deg"]], None, [d["focus_min_mm"], d["focus_max_mm"]],
                     None, [d["translation_mm"]]])
    return rows


SWEEP_RANGES = Figure(
    cites="mitsweep sweep-range",
    commands=tuple(f".venv/bin/mitsweep sweep-range scenes/{s}.toml --json" for s in _SETUPS),
    rows=_sweep_design_rows)

#: (setup, --field) per row of docs/reference/tracer.md's traced sweep-range table
_TRACED = (("sphere", "plane"), ("paraboloid", "plane"), ("paraboloid", "mirror"),
           ("paraboloid_tilted", "plane"), ("paraboloid_tilted", "fov"),
           ("paraboloid_tilted", "mirror"))


def _traced_rows(outputs: list[str]) -> Rows:
    """setup | field | analytic | traced | farthest focus at (x, y mm; depth m)."""
    rows: Rows = []
    for (_, field_name), text in zip(_TRACED, outputs):
        d = _json(text)
        at = d["traced_focus_max_at"]
        analytic = [d["focus_min_mm"], d["focus_max_mm"]] if field_name == "plane" else []
        rows.append([None, None, analytic, [d["traced_focus_min_mm"], d["traced_focus_max_mm"]],
                     [at["x_mm"], abs(at["y_mm"]), at["depth_mm"] / 1000]])
    return rows


TRACED_SWEEP_RANGES = Figure(
    cites="mitsweep sweep-range scenes/X.toml --verify",
    commands=tuple(f".venv/bin/mitsweep sweep-range scenes/{s}.toml --verify --field {f} --json"
                   for s, f in _TRACED),
    rows=_traced_rows, slow=True)


def _table1_rows(outputs: list[str]) -> Rows:
    """sweep range | V_avg | centre tan | centre rad | periphery tan | periphery rad, and
    the conventional camera's V_avg."""
    d = _json(outputs[0])
    rows: Rows = []
    for row in d["rows"]:
        k = row["kurtosis"]
        rows.append([[row["focus_min_mm"], row["focus_max_mm"]], [row["v_avg"]],
                     [k["center"]["tangential"]], [k["center"]["radial"]],
                     [k["periphery"]["tangential"]], [k["periphery"]["radial"]]])
    rows.append([None, [d["conventional"]["v_avg"]], [], [], [], []])
    return rows


TABLE1_SPHERE = Figure(
    cites="table1",
    commands=(".venv/bin/mitsweep table1 scenes/sphere.toml --json",),
    rows=_table1_rows, slow=True)

TABLE1_PARABOLOID = Figure(
    cites="table1",
    commands=(".venv/bin/mitsweep table1 scenes/paraboloid.toml --json",),
    rows=_table1_rows, slow=True)


def _calibration_rows(outputs: list[str]) -> Rows:
    """setup | worst centre error | worst radius error, for the three setups."""
    worst = _json(outputs[0])["worst"]
    return [[None, [worst[s]["centre_error_px"]], [worst[s]["radius_error_px"]]]
            for s in ("paraboloid", "paraboloid_tilted", "sphere")]


CALIBRATION_ERRORS = Figure(
    cites="scripts/calibration_errors.py",
    commands=(".venv/bin/python scripts/calibration_errors.py --json",),
    rows=_calibration_rows, slow=True)


def _weight_bench_rows(outputs: list[str]) -> Rows:
    """case (size px, σ) | oracle NSR | oracle dB | before, model, blind, mirror loss (dB)."""
    rows: Rows = []
    for case in _json(outputs[0])["independent_blur"]:
        size, sigma = re.fullmatch(r"independent blur (\d+) px, sigma ([\d.e-]+)",
                                   case["case"]).groups()
        rows.append([[float(size), float(sigma)], [case["oracle"]["weight"]],
                     [case["oracle"]["psnr_db"]],
                     *([case[k]["loss_db"]] for k in ("before", "model", "blind", "mirror"))])
    return rows


WEIGHT_BENCH_BLUR = Figure(
    cites="scripts/weight_bench.py --sizes 512 2048",
    commands=(".venv/bin/python scripts/weight_bench.py --sizes 512 2048 --json",),
    rows=_weight_bench_rows, slow=True)


def _bench_render(outputs: list[str]) -> dict:
    return json.loads(outputs[0])["targets"]["render"]["result"]


def _ground_truth_rows(outputs: list[str]) -> Rows:
    """spp | old CPU s | old two-seed | new CPU s | new two-seed, pinhole at 16 and 64 spp."""
    found = {(r["spp"], r["method"]): r for r in _bench_render(outputs)["ground_truth"]
             if r["mode"] == "pinhole"}
    return [[[spp], None, [found[spp, "old"]["two_seed_psnr_db"]], None,
             [found[spp, "new"]["two_seed_psnr_db"]]] for spp in (16, 64)]


def _mesh_rows(outputs: list[str]) -> Rows:
    """mesh bound | triangles | sag error | PSF L1 | render s."""
    rows: Rows = []
    for r in _bench_render(outputs)["mesh_accuracy"]:
        if r["mesh"] == "analytic sphere":      # no triangles; no sag error by definition
            rows.append([None, [], [0.0], [r["psf_l1"]], None])
        else:
            bound = float(r["mesh"].split()[-1])
            rows.append([[bound], [r["triangles"]], [r["sag_error_mm"]], [r["psf_l1"]], None])
    return rows


def _error_vs_time_rows(outputs: list[str]) -> Rows:
    """continuous and 8 planes: relative RMSE / s at 16, 64 and 256 spp."""
    rows = _bench_render(outputs)["error_vs_time"]["rows"]
    return [[None, *([r["continuous_rel_rmse"], None] for r in rows)],
            [None, *([r["planes_rel_rmse"], None] for r in rows)]]


_BENCH = dict(cites="mitsweep bench render", commands=(".venv/bin/mitsweep bench all --json",),
              recorded="docs/benchmarks.json", timings=True)
GROUND_TRUTH = Figure(rows=_ground_truth_rows, **_BENCH)
MESH_ACCURACY = Figure(rows=_mesh_rows, **_BENCH)
ERROR_VS_TIME = Figure(rows=_error_vs_time_rows, **_BENCH)


def _demo(setup: str) -> str:
    """``mitsweep demo`` on a bundled setup, in a temporary directory; prints its report
    and evaluation as one JSON object."""
    both = ("import json, sys; print(json.dumps({'report': json.load(open(sys.argv[1])), "
            "'evaluation': json.load(open(sys.argv[2]))}))")
    return (f'd=$(mktemp -d) && trap \'rm -rf "$d"\' EXIT && '
            f'.venv/bin/mitsweep demo --setup scenes/{setup}.toml --out "$d/o" >/dev/null 2>&1 && '
            f'.venv/bin/python -c "{both}" "$d/o/report.json" "$d/o/evaluation.json"')


def _demo_psnr(outputs: list[str], rows: Sequence[Sequence[str]]) -> Rows:
    """image | sphere | paraboloid | tilted paraboloid: PSNR (dB) inside the mirror, one
    row per list of images."""
    psnr = [{k: v["psnr"] for k, v in _json(t)["report"]["evaluation"].items()} for t in outputs]
    return [[None, *([p[i] for i in images] for p in psnr)] for images in rows]


def _demo_rows(outputs: list[str]) -> Rows:
    """The noise-free images: focused, sweep, EDOF, F11."""
    return _demo_psnr(outputs, (["focused"], ["sweep"], ["edof"], ["stopped"]))


def _demo_noisy_rows(outputs: list[str]) -> Rows:
    """EDOF and F11 at 50 / 2 / 0.5 lux."""
    return _demo_psnr(outputs, (["edof_50lux", "edof_2lux", "edof_0.5lux"],
                                ["stopped_50lux", "stopped_2lux", "stopped_0.5lux"]))


def _demo_radius_rows(outputs: list[str]) -> Rows:
    """radius (px) | per-radius PSNR of the focused image and the EDOF, on the sphere."""
    scene = _json(outputs[0])["evaluation"]["scenes"]["scene_000"]
    return [[None, *([p] for p in scene[image]["per_radius"]["psnr"])]
            for image in ("focused", "edof")]


DEMO = Figure(cites="mitsweep demo --setup scenes/NAME.toml",
              commands=tuple(_demo(s) for s in _SETUPS), rows=_demo_rows, slow=True)
DEMO_NOISY = Figure(cites="two runs of the same", commands=DEMO.commands,
                    rows=_demo_noisy_rows, slow=True)
DEMO_RADIUS = Figure(cites="report.md", commands=(_demo("sphere"),), rows=_demo_radius_rows,
                     slow=True)


def _design_rows(outputs: list[str]) -> Rows:
    """setup | lux | worst, mean MSE lin → opt (dB) | V_avg | worst at (r, l) lin / opt |
    held-out worst (dB) | bound gap (%) | brute force, per case of scripts/design_study.py."""
    def db(mse: float) -> float:
        return -10 * math.log10(mse)
    rows: Rows = []
    for r in json.loads(outputs[0]):
        wl, wo = r["linear_worst_at"], r["optimized_worst_at"]
        rows.append([None, [r["lux"]],
                     [db(r["linear_worst_mse"]), db(r["optimized_worst_mse"])],
                     [db(r["linear_mean_mse"]), db(r["optimized_mean_mse"])],
                     [r["linear_v_avg"], r["optimized_v_avg"]],
                     [wl["radius_mm"], wl["depth_mm"], wo["radius_mm"], wo["depth_mm"]],
                     [db(r["heldout_linear_worst_mse"]), db(r["heldout_optimized_worst_mse"])],
                     [100 * r["relative_gap"]], None])
    return rows


DESIGN_PREDICTED = Figure(
    cites="scripts/design_study.py",
    commands=(".venv/bin/python scripts/design_study.py out/design && "
              "cp out/design/predicted.json docs/reference/design_study_predicted.json",),
    rows=_design_rows, recorded="docs/reference/design_study_predicted.json")


def _photo_corpus_rows(outputs: list[str]) -> Rows:
    """photo | mirror, outline | size, format | reference centre | radius | tolerance |
    error (time) of --free and the +9 %, -35 %, +35 % setups, per photo of
    scripts/photo_corpus.py (times not compared)."""
    rows: Rows = []
    for r in json.loads(outputs[0]):
        runs = [r["runs"][k] for k in ("free", "+0.09", "-0.35", "+0.35")]
        rows.append([None, None, list(r["size_px"]), list(r["centre_px"]), [r["radius_px"]],
                     [r["tolerance_px"]],
                     *([None] if run["error_px"] is None else [run["error_px"], None]
                       for run in runs)])
    return rows


PHOTO_CORPUS = Figure(
    cites="scripts/photo_corpus.py",
    commands=(".venv/bin/python scripts/photo_corpus.py "
              "--json docs/reference/photo_corpus.json",),
    rows=_photo_corpus_rows, recorded="docs/reference/photo_corpus.json", timings=True)


#: The terms of scripts/budget_study.py's table, in its column order.
_BUDGET_TERMS = ("information", "depth", "mismatch", "monte_carlo", "sensor", "weight")


def _budget_rows(outputs: list[str]) -> Rows:
    """image | region | pixels | each term (MSE x 1e4, – where not measured) | total |
    PSNR: per budget of scripts/budget_study.py, the whole mirror then each radial bin."""
    def cells(terms: dict, mse: float, psnr: float | None) -> list:
        return [*(None if terms.get(t) is None else [1e4 * terms[t]] for t in _BUDGET_TERMS),
                [1e4 * mse], None if psnr is None else [psnr]]
    rows: Rows = []
    for b in _json(outputs[0])["budgets"].values():
        t, r = b["total"], b["per_radius"]
        rows.append([None, None, [t["pixels"]], *cells(t["terms"], t["mse"], t["psnr"])])
        e = r["edges_px"]
        for i, n in enumerate(r["pixels"]):
            if n:
                rows.append([None, [e[i], e[i + 1]], [n],
                             *cells({k: v[i] for k, v in r["terms"].items()}, r["mse"][i],
                                    r["psnr"][i])])
    return rows


BUDGET_STUDY = Figure(
    cites="scripts/budget_study.py",
    commands=(".venv/bin/python scripts/budget_study.py OUT "
              "--json docs/reference/budget_study.json",),
    rows=_budget_rows, recorded="docs/reference/budget_study.json")


#: Every checked figure, by the name its page's marker gives.
FIGURES: dict[str, Figure] = {
    "sweep-ranges": SWEEP_RANGES,
    "traced-sweep-ranges": TRACED_SWEEP_RANGES,
    "table1-sphere": TABLE1_SPHERE,
    "table1-paraboloid": TABLE1_PARABOLOID,
    "calibration-errors": CALIBRATION_ERRORS,
    "weight-bench-blur": WEIGHT_BENCH_BLUR,
    "design-predicted": DESIGN_PREDICTED,
    "photo-corpus": PHOTO_CORPUS,
    "budget-study": BUDGET_STUDY,
    "demo-psnr": DEMO,
    "demo-psnr-noisy": DEMO_NOISY,
    "demo-psnr-per-radius": DEMO_RADIUS,
    "bench-render-ground-truth": GROUND_TRUTH,
    "bench-render-mesh": MESH_ACCURACY,
    "bench-render-error-vs-time": ERROR_VS_TIME,
}


def report() -> list[str]:
    """One line per table that shows a number: where it is and how it is checked."""
    lines = []
    for t in tables():
        if t.has_numbers or t.kind != "none":
            how = t.marker.get("figures", "NO MARKER")
            if t.kind == "check" and how in FIGURES:
                figure = FIGURES[how]
                how += (f" (against {figure.recorded}" if figure.recorded else " (rerun")
                how += f", tolerance {t.marker.get('tolerance', 'printed')}"
                how += ", slow)" if figure.slow and not figure.recorded else ")"
            lines.append(f"{t.where}: {how}")
    return lines


if __name__ == "__main__":
    print("\n".join(report()))
