"""The code blocks of the README and the docs, read as the tests run them.

Every fenced block tagged ``bash``, ``console`` or ``python`` in ``README.md`` and
``docs/**/*.md`` is a snippet. Markers, in an HTML comment on the lines just above the
fence (blank lines between are allowed; several markers may share one comment,
separated by ``;``):

``<!-- skip: REASON -->``
    the block cannot run here (a CUDA GPU, the real rig, your own photo, a cluster);
    the test counts it and reports the reason.
``<!-- slow -->``
    the block runs only with ``-m slow`` (long renders, whole datasets).
``<!-- session: NAME -->``
    the blocks of one page that share NAME run in order, in one temporary directory and,
    for Python, one namespace (a later block uses an earlier one's files and names).
``<!-- needs: MODULE -->``
    the block imports an optional package (PyTorch, JAX); where it is not installed the
    block is skipped, with that reason.
``<!-- file: NAME -->`` (on a block of any other language, e.g. ``toml``)
    the block is written to NAME in its session's directory before the next block runs.
``<!-- printed -->`` (on a ``text`` block right after a ``python`` block)
    what the Python block prints, checked as a console block's output is.
``<!-- tolerance: REL -->``
    for a ``console`` block or a ``printed`` output: printed numbers must match within this relative tolerance
    (default 1e-6, i.e. exactly as printed); numbers followed by ``s`` (seconds) are
    never compared, they depend on the machine.

A ``console`` block holds commands after ``$ `` and, after each, the lines it prints; a
line ``...`` in the expected output stands for any number of printed lines. Blocks run
in a fresh temporary directory that looks like the repository's root (its ``.venv``,
``scenes``, ``scripts``, ``examples``, ``tests``, ``mitsweep`` and ``docs`` linked into
it), so a command copied from the docs into a fresh clone's root runs the same way.
``.venv/bin`` is *not* on ``PATH``: a block calls ``.venv/bin/mitsweep`` and
``.venv/bin/python`` as the docs tell a reader to.
"""

from __future__ import annotations

import importlib.util
import json
import os
import re
import subprocess
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LANGS = ("bash", "console", "python")
#: What a temporary directory links from the repository's root.
LINKED = (".venv", "scenes", "scripts", "examples", "tests", "mitsweep", "docs", "pyproject.toml")

_FENCE = re.compile(r"^(?P<indent>[ ]{0,3})(?P<fence>`{3,})(?P<lang>[\w-]*)[^\n]*\n(?P<body>.*?)^(?P=indent)(?P=fence)\s*$",
                    re.M | re.S)
_NUMBER = re.compile(r"[-+]?(?:\d+\.\d*|\.\d+|\d+)(?:[eE][-+]?\d+)?")


@dataclass
class Snippet:
    """One fenced block: where it is, its code and its markers."""
    path: Path
    line: int
    lang: str
    code: str
    skip: str | None = None
    slow: bool = False
    session: str | None = None
    tolerance: float = 1e-6
    markers: dict = field(default_factory=dict)
    #: for a python block: the lines a ``text`` block marked ``<!-- printed -->`` right
    #: after it says it prints
    expected: list | None = None

    @property
    def where(self) -> str:
        return f"{self.path.relative_to(ROOT).as_posix()}:{self.line}"


def doc_files() -> list[Path]:
    """README.md and every Markdown page of docs/ (not the build's output)."""
    pages = [p for p in sorted((ROOT / "docs").rglob("*.md")) if "_build" not in p.parts]
    return [ROOT / "README.md", *pages]


def _markers(text_before: str) -> dict:
    """The markers of the HTML comment that ends ``text_before`` (blank lines allowed)."""
    text = text_before.rstrip()
    if not text.endswith("-->"):
        return {}
    start = text.rfind("<!--")
    if start < 0:
        return {}
    body = text[start + 4:-3]
    out = {}
    for part in re.split(r";\s*(?=(?:skip|slow|session|tolerance|needs|printed|file)\b)", body):
        key, _, value = part.partition(":")
        key = key.strip().lower()
        if key in ("skip", "slow", "session", "tolerance", "needs", "printed", "file"):
            out[key] = value.strip()
    return out


def snippets(paths=None) -> list[Snippet]:
    """Every bash/console/python block of the given pages (default: all), in order."""
    found = []
    for path in paths or doc_files():
        text = path.read_text(encoding="utf-8")
        for m in _FENCE.finditer(text):
            lang = m.group("lang").lower()
            marks = _markers(text[:m.start()])
            if lang == "text" and "printed" in marks and found and found[-1].path == path \
                    and found[-1].lang == "python":
                found[-1].expected = m.group("body").splitlines()
                if "tolerance" in marks:
                    found[-1].tolerance = float(marks["tolerance"])
                continue
            if "file" in marks and lang not in LANGS:
                lang = "file"       # written to that file, in its session's directory
            elif lang not in LANGS:
                continue
            s = Snippet(path, text.count("\n", 0, m.start()) + 1, lang, m.group("body"), markers=marks)
            if "skip" in marks:
                s.skip = marks["skip"] or "no reason given"
            if "needs" in marks and s.skip is None:
                missing = [n for n in marks["needs"].replace(",", " ").split()
                           if importlib.util.find_spec(n) is None]
                if missing:
                    s.skip = f"needs {', '.join(missing)} (optional, not installed here)"
            s.slow = "slow" in marks
            s.session = marks.get("session") or None
            if "tolerance" in marks:
                s.tolerance = float(marks["tolerance"])
            found.append(s)
    return found


def workdir(base: Path) -> Path:
    """A fresh directory that looks like the repository's root (links to its parts)."""
    for name in LINKED:
        if (ROOT / name).exists():
            (base / name).symlink_to(ROOT / name)
    return base


def environment() -> dict:
    env = dict(os.environ)
    env.pop("VIRTUAL_ENV", None)
    venv_bin = str(ROOT / ".venv" / "bin")
    env["PATH"] = os.pathsep.join(p for p in env.get("PATH", "").split(os.pathsep)
                                  if p and Path(p).resolve() != Path(venv_bin).resolve())
    env.setdefault("MITSWEEP_BACKEND", "llvm")
    env["MPLBACKEND"] = "Agg"
    env["PYTHONDONTWRITEBYTECODE"] = "1"
    return env


def console_commands(code: str) -> list[tuple[str, list[str]]]:
    """A console block as (command, expected output lines) pairs."""
    pairs: list[tuple[str, list[str]]] = []
    for line in code.splitlines():
        if line.startswith("$ "):
            pairs.append((line[2:], []))
        elif pairs:
            pairs[-1][1].append(line)
    return pairs


def _compare_line(expected: str, got: str, rel: float) -> str | None:
    """None if ``got`` shows ``expected``: the same words, the same numbers within
    ``rel`` (numbers followed by an ``s`` unit are not compared)."""
    def split(s):
        words = _NUMBER.split(s)
        nums = _NUMBER.findall(s)
        return [w.split() for w in words], nums
    ew, en = split(expected)
    gw, gn = split(got)
    if ew != gw or len(en) != len(gn):
        return f"expected {expected!r}, got {got!r}"
    units = [ew[i + 1][0] if ew[i + 1] else "" for i in range(len(en))]
    for e, g, unit in zip(en, gn, units):
        if unit == "s":
            continue
        a, b = float(e), float(g)
        # a number printed to d decimals is checked to half its last digit as well
        decimals = len(e.split(".")[1]) if "." in e and "e" not in e.lower() else 0
        slack = max(rel * abs(a), 0.5 * 10.0 ** -decimals) if decimals else rel * abs(a)
        if abs(a - b) > slack:
            return f"{e} documented, {g} printed (tolerance {slack:g}): {got!r}"
    return None


def check_output(expected: list[str], printed: str, rel: float) -> list[str]:
    """The mismatches between a console block's expected lines and what was printed:
    each expected line must appear, in order; ``...`` skips any lines."""
    lines = [l.rstrip() for l in printed.splitlines() if l.strip()]
    problems, i = [], 0
    gap = False
    for exp in (e.rstrip() for e in expected):
        if not exp.strip():
            continue
        if exp.strip() == "...":
            gap = True
            continue
        # the next printed line, or with a gap the first one whose words match
        while i < len(lines):
            why = _compare_line(exp, lines[i], rel)
            if why is None:
                break
            if not gap and _compare_line(exp, lines[i], float("inf")) is not None:
                i += 1
                gap = True  # tolerate extra lines (warnings) before a match
                continue
            if not gap or _compare_line(exp, lines[i], float("inf")) is None:
                problems.append(why)
                break
            i += 1
        else:
            problems.append(f"not printed: {exp!r}")
            break
        i += 1
        gap = False
    return problems


# -- the driver: runs a session's blocks in one process (one Python namespace) -----------

def _drive(spec_file: str) -> None:
    spec = json.loads(Path(spec_file).read_text())
    namespace: dict = {"__name__": "__main__"}
    results = []
    import contextlib
    import io
    import traceback
    for block in spec["blocks"]:
        if block["lang"] == "file":
            Path(block["file"]).write_text(block["code"])
            results.append({"ok": True, "output": ""})
            continue
        if block["lang"] == "python":
            out = io.StringIO()
            ok = True
            try:
                with contextlib.redirect_stdout(out), contextlib.redirect_stderr(out):
                    exec(compile(block["code"], block["where"], "exec"), namespace)
            except BaseException:  # noqa: BLE001 - reported with the block
                ok = False
                out.write(traceback.format_exc())
            results.append({"ok": ok, "output": out.getvalue()})
            continue
        if block["lang"] == "bash":
            commands = [(block["code"], None)]
        else:
            commands = console_commands(block["code"])
        outputs, ok = [], True
        # One bash process per block, so that a command ending in & (a simulator) keeps
        # running for the block's later commands; it is stopped when the block ends.
        script = ["set -euo pipefail", "trap 'kill $(jobs -p) 2>/dev/null || true' EXIT"]
        for k, (cmd, _) in enumerate(commands):
            script += [f"printf '\\n@@CMD {k}\\n'; printf '\\n@@CMD {k}\\n' >&2", cmd]
        script.append(f"printf '\\n@@CMD {len(commands)}\\n'")
        Path("._block.sh").write_text("\n".join(script) + "\n")
        with open("._out", "w") as so, open("._err", "w") as se:
            try:
                rc = subprocess.run(["bash", "._block.sh"], stdout=so, stderr=se,
                                    timeout=spec["timeout"]).returncode
            except subprocess.TimeoutExpired:
                rc = 124
        out_parts = re.split(r"\n@@CMD (\d+)\n", "\n" + Path("._out").read_text())
        err_parts = re.split(r"\n@@CMD (\d+)\n", "\n" + Path("._err").read_text())
        out_by = dict(zip(out_parts[1::2], out_parts[2::2]))
        err_by = dict(zip(err_parts[1::2], err_parts[2::2]))
        for k, (cmd, expected) in enumerate(commands):
            if str(k) not in out_by:
                break
            done = str(k + 1) in out_by
            outputs.append({"command": cmd, "rc": 0 if done else rc, "stdout": out_by[str(k)],
                            "stderr": err_by.get(str(k), ""), "expected": expected})
        ok = rc == 0
        for name in ("._block.sh", "._out", "._err"):
            Path(name).unlink()
        results.append({"ok": ok, "commands": outputs})
    Path(spec["results"]).write_text(json.dumps(results))


def run_session(blocks: list[Snippet], timeout: float = 1800) -> list[dict]:
    """Run the blocks in order in one fresh directory; their results, one per block."""
    with tempfile.TemporaryDirectory(prefix="mitsweep-doc-") as tmp:
        base = workdir(Path(tmp))
        spec = {"blocks": [{"lang": b.lang, "code": b.code, "where": b.where,
                            "file": b.markers.get("file")} for b in blocks],
                "results": str(Path(tmp) / ".results.json"), "timeout": timeout}
        (Path(tmp) / ".spec.json").write_text(json.dumps(spec))
        proc = subprocess.run([str(ROOT / ".venv" / "bin" / "python"), str(Path(__file__)),
                               str(Path(tmp) / ".spec.json")], cwd=base, env=environment(),
                              capture_output=True, text=True, timeout=timeout * len(blocks) + 60)
        res = Path(spec["results"])
        if not res.is_file():
            raise RuntimeError(f"the snippet driver failed:\n{proc.stdout}\n{proc.stderr}")
        return json.loads(res.read_text())


if __name__ == "__main__":
    _drive(sys.argv[1])
