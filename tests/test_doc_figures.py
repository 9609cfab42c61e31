"""The numbers of the docs' tables are the numbers the commands print today.

Every table of docs/ that shows a number is tied, by a marker above it, to the figure of
``tests/doc_figures.py`` that reproduces it (its command is re-run and each documented
number compared within the marker's tolerance), or declared a timing table (the
paragraph above must name the command and the machine), a generated table (checked by
its own test) or, with a reason, not checked. ``pytest -s`` prints the list. Figures
whose commands take more than about 10 s run with ``-m slow``.
"""

import pytest

from doc_figures import FIGURES, MACHINE, ROOT, compare, numbers, slack, tables

ALL = tables()
CHECKED = [t for t in ALL if t.kind == "check"]


def test_every_table_with_numbers_has_a_marker():
    bare = [f"{t.where}: {t.header}" for t in ALL if t.has_numbers and t.kind == "none"]
    assert not bare, ("tables showing numbers without a `<!-- figures: ... -->` marker "
                      "(see tests/doc_figures.py):\n" + "\n".join(bare))


def test_every_marker_names_a_known_figure_once_per_page_kind():
    unknown = [f"{t.where}: {t.marker['figures']!r}" for t in CHECKED
               if t.marker["figures"] not in FIGURES]
    assert not unknown, "markers naming no figure of tests/doc_figures.py: " + ", ".join(unknown)
    used = {t.marker["figures"] for t in CHECKED}
    assert not set(FIGURES) - used, f"figures no page uses: {sorted(set(FIGURES) - used)}"


def test_every_unchecked_table_says_why():
    silent = [t.where for t in ALL if t.kind in ("not checked", "generated")
              and "(" not in t.marker["figures"]]
    assert not silent, "`not checked (REASON)` / `generated (TEST)` without a reason: " \
        + ", ".join(silent)


def test_timing_tables_name_their_command_and_machine():
    timed = [t for t in ALL if t.kind == "timing" or (
        t.kind == "check" and t.marker["figures"] in FIGURES
        and FIGURES[t.marker["figures"]].timings)]
    problems = [f"{t.where}: the paragraph above a timing table must cite its command"
                for t in timed if "`" not in t.above]
    problems += [f"{t.where}: the paragraph above a timing table must say which machine "
                 "measured it" for t in timed if not MACHINE.search(t.above)]
    assert not problems, "\n".join(problems)


@pytest.mark.parametrize("table", CHECKED, ids=[t.where for t in CHECKED])
def test_the_page_cites_the_figures_command(table):
    figure = FIGURES[table.marker["figures"]]
    assert figure.cites in table.above, \
        f"{table.where}: the paragraph above the table should cite `{figure.cites}`"


@pytest.mark.parametrize("table", [
    pytest.param(t, marks=[pytest.mark.slow] if FIGURES[t.marker["figures"]].slow
                 and FIGURES[t.marker["figures"]].recorded is None else [],
                 id=t.where) for t in CHECKED if t.marker["figures"] in FIGURES])
def test_documented_numbers_are_what_the_command_prints(table):
    figure = FIGURES[table.marker["figures"]]
    problems = compare(table, figure.rows(figure.outputs()))
    assert not problems, "\n".join(problems)


def test_report(capsys):
    """``pytest -s`` lists every numeric table and how it is checked."""
    from doc_figures import report
    with capsys.disabled():
        print("\n" + "\n".join(f"  {line}" for line in report()))


@pytest.mark.parametrize("cell, want", [
    ("339.000–364.249", [339.0, 364.249]),
    ("(−2.79, ±21.37); 10 m", [-2.79, 21.37, 10.0]),
    ("12,403", [12403.0]),
    ("1.58e+03 → 2.82e+03", [1580.0, 2820.0]),
    ("237°", [237.0]),
    ("−0.75 ± 0.03 [−0.85, −0.70]", [-0.75, 0.03, -0.85, -0.70]),
])
def test_numbers_are_read_as_written(cell, want):
    assert numbers(cell) == pytest.approx(want)


@pytest.mark.parametrize("written, tolerance, allowed", [
    ("364.249", "printed", 0.0005), ("6.6e6", "printed", 0.05e6), ("975", "printed", 0.5),
    ("20.0", "1%", 0.2), ("20.0", "printed, 1%", 0.25), ("3", "±0.1", 0.1),
])
def test_tolerance_is_half_the_last_digit_plus_what_the_marker_adds(written, tolerance, allowed):
    assert slack(written, tolerance) == pytest.approx(allowed)


def test_a_wrong_number_is_caught():
    from doc_figures import Table
    table = Table(ROOT / "docs" / "x.md", 1, ["a", "b"], [["x", "339.00–364.26 mm"]], "", {})
    assert compare(table, [[None, [339.0, 364.2485]]])
    assert not compare(table, [[None, [339.0, 364.2551]]])


def test_a_marker_reads_its_figure_tolerance_and_a_reason_with_semicolons(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("Text `cmd` on a 2-core machine:\n\n<!-- figures: x; tolerance: 1% -->\n"
                    "| a |\n|---|\n| 1 |\n\n<!-- figures: not checked (one; two) -->\n"
                    "| b |\n|---|\n| 2 |\n")
    first, second = tables([page])
    assert first.marker == {"figures": "x", "tolerance": "1%"} and first.kind == "check"
    assert first.above == "Text `cmd` on a 2-core machine:"
    assert second.marker == {"figures": "not checked (one; two)"}
    assert second.kind == "not checked"
