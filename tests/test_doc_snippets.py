"""Every shell command and Python snippet of the README and the docs runs, as written,
in a fresh directory laid out like the repository's root (``tests/doc_snippets.py``
says how blocks are found, marked and run). A ``console`` block's printed lines are
checked against what its commands print: the same words, the same numbers within the
block's stated tolerance (default: to half the last printed digit), times in seconds
not compared. A block that cannot run here says why in the page (``<!-- skip: ... -->``)
and is reported as skipped with that reason; long ones are marked slow.

Counts (``pytest tests/test_doc_snippets.py -rs``; with ``-m "slow or not slow"`` for
the slow ones) are printed by ``test_snippet_inventory``."""

import re
from collections import defaultdict

import pytest

import doc_snippets as ds

ALL = ds.snippets()


def _groups():
    """Sessions (a page's blocks sharing a name) and lone blocks, in page order."""
    sessions: dict = defaultdict(list)
    groups = []
    for s in ALL:
        if s.session:
            key = (s.path, s.session)
            if key not in sessions:
                groups.append(sessions[key])
            sessions[key].append(s)
        else:
            groups.append([s])
    params = []
    for g in groups:
        marks = [pytest.mark.slow] if any(s.slow for s in g) else []
        params.append(pytest.param(g, id=g[0].where + (f"[{g[0].session}]" if g[0].session else ""),
                                   marks=marks))
    return params


def _report(block, result) -> str:
    if block.lang in ("python", "file"):
        return f"{block.where} (python):\n{result['output'][-4000:]}"
    parts = [f"{block.where} ({block.lang}):"]
    for c in result["commands"]:
        parts.append(f"$ {c['command']}\n[rc {c['rc']}]\n{c['stdout'][-2000:]}\n{c['stderr'][-3000:]}")
    return "\n".join(parts)


@pytest.mark.parametrize("group", _groups())
def test_snippet_runs(group):
    # a skipped block of a session is left out (the inventory reports it); the rest run
    skipped = [s for s in group if s.skip]
    group = [s for s in group if not s.skip]
    if all(s.lang == "file" for s in group):
        pytest.skip("; ".join(f"{s.where}: {s.skip}" for s in skipped))
    results = ds.run_session(group)
    assert len(results) == len(group), "a block of the session did not run"
    for block, result in zip(group, results):
        assert result["ok"], _report(block, result)
        if block.lang == "file":
            continue
        if block.lang == "python":
            if block.expected is not None:
                problems = ds.check_output(block.expected, result["output"], block.tolerance)
                assert not problems, (f"{block.where} printed what the page does not show:\n"
                                      + "\n".join(problems) + f"\n--- printed:\n{result['output']}")
            continue
        if block.lang != "console":
            continue
        for c in result["commands"]:
            problems = ds.check_output(c["expected"], c["stdout"] + c["stderr"], block.tolerance)
            assert not problems, (f"{block.where}: `{c['command']}` printed what the page "
                                  f"does not show:\n" + "\n".join(problems)
                                  + f"\n--- printed:\n{c['stdout']}{c['stderr']}")


#: A command at the start of a line, after ;, &&, ||, | or $( that would need the
#: virtual environment on PATH: a fresh clone has no ``mitsweep`` and maybe no ``python``.
_BARE = re.compile(r"(?:^|[;&|]\s*|\$\(\s*|^\$\s+)(mitsweep|python3?|pip|pytest|sphinx-build)\b", re.M)


def test_commands_name_the_virtual_environment():
    """Shell blocks call ``.venv/bin/mitsweep`` / ``.venv/bin/python``, never the bare
    names that only work once the environment is activated (skipped blocks included:
    they are copied too)."""
    bad = []
    for s in ALL:
        if s.lang in ("python", "file"):
            continue
        for line in s.code.splitlines():
            code = line.split("#", 1)[0] if s.lang == "bash" else line
            if s.lang == "console" and not line.startswith("$ "):
                continue
            code = code[2:] if s.lang == "console" else code
            if _BARE.search(code.strip()):
                bad.append(f"{s.where}: {line.strip()}")
    assert not bad, "bare commands (write .venv/bin/...):\n" + "\n".join(bad)


def test_skips_say_why_and_markers_are_known():
    unexplained = [s.where for s in ALL if s.skip is not None and not s.skip.strip()]
    assert not unexplained
    for s in ALL:
        if s.lang == "console":
            assert ds.console_commands(s.code), f"{s.where}: a console block with no `$ ` command"


def test_snippet_inventory(capsys):
    """The counts: what runs by default, what only with -m slow, what is skipped and why."""
    code = [s for s in ALL if s.lang != "file"]
    default = [s for s in code if not s.skip and not s.slow]
    slow = [s for s in code if not s.skip and s.slow]
    skipped = [s for s in code if s.skip]
    assert len(ALL) >= 30 and default, "the docs' snippets were not found"
    with capsys.disabled():
        print(f"\ndoc snippets: {len(code)} blocks; {len(default)} run by default, {len(slow)} more "
              f"with -m slow, {len(skipped)} skipped:")
        for s in skipped:
            print(f"  {s.where}: {s.skip}")


def test_console_output_check_catches_drift():
    """The comparison itself: words must match, numbers within tolerance, seconds free."""
    assert ds.check_output(["centre row 255.443 px"], "centre row 255.443 px\n", 1e-6) == []
    assert ds.check_output(["centre row 255.443 px"], "centre row 255.649 px\n", 1e-6)
    assert ds.check_output(["done in 1.06 s"], "done in 9.93 s\n", 1e-6) == []
    assert ds.check_output(["a 1.00", "...", "c 3"], "a 1.004\nb\nc 3\n", 1e-6) == []
    assert ds.check_output(["x 0.510000 s"], "warning: w\nx 0.510000 s\n", 1e-6) == []
    assert ds.check_output(["pitch 0.02"], "pitch 0.021\n", 0.1) == []
    assert ds.check_output(["value 52 %"], "value 42.5 %\n", 1e-6)
    assert ds.check_output(["missing"], "something else\n", 1e-6)
