#!/usr/bin/env bash
# The documentation site: installs what is missing first (scripts/bootstrap.sh, then the
# docs extra: Sphinx, numpydoc, MyST, Furo), then builds docs/ into docs/_build/html with
# warnings as errors. Extra arguments go to sphinx-build (e.g. -E to rebuild everything).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
"$root/scripts/bootstrap.sh"
cd "$root"
stamp=".venv/.mitsweep-docs-installed"
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ] ||
   ! .venv/bin/python -c "import sphinx, numpydoc, myst_parser, furo, latex2mathml" 2>/dev/null; then
    echo "docs: installing the docs extra into .venv (log: .venv/pip-install-docs.log)" >&2
    if ! .venv/bin/python -m pip install -q -e ".[docs]" >.venv/pip-install-docs.log 2>&1; then
        tail -n 30 .venv/pip-install-docs.log >&2
        echo "docs: pip install failed (full log: .venv/pip-install-docs.log)" >&2
        exit 1
    fi
    touch "$stamp"
fi
out="docs/_build/html"
.venv/bin/python -m sphinx -W --keep-going -b html "$@" docs "$out"
echo "docs: the site is in $root/$out (open $root/$out/index.html)"
