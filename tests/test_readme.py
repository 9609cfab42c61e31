"""The README is a landing page: at most 10 KB; what mitsweep is, one picture that
exists, the two commands exactly as CI runs them, a Python example (run, with its
printed figures checked, by tests/test_doc_snippets.py), and links into the docs that
all resolve."""

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"


def test_readme_is_a_landing_page_of_at_most_10_kb():
    assert README.stat().st_size <= 10 * 1024, README.stat().st_size


def test_readme_gives_the_two_commands_ci_runs():
    text = README.read_text()
    assert re.search(r"^bash scripts/main\.sh\b", text, re.M)
    assert re.search(r"^bash scripts/test\.sh\b", text, re.M)
    assert "bash scripts/test.sh" in (ROOT / ".ci" / "run").read_text()


def test_readme_picture_and_links_resolve():
    text = README.read_text()
    pictures = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", text)
    assert len(pictures) == 1 and (ROOT / pictures[0]).is_file(), pictures
    links = [l for l in re.findall(r"(?<!!)\[[^\]]+\]\(([^)#]+)[^)]*\)", text) if "://" not in l]
    assert len(links) >= 10
    missing = [l for l in links if not (ROOT / l).is_file()]
    assert not missing, missing
    assert "```python" in text
