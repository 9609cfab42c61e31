#!/usr/bin/env bash
# Screenshots of the built documentation (docs/images/screenshots/): the API index, a
# typed signature, and equations rendered with no script and no network (MathML).
# Needs the docs built (scripts/docs.sh) and a headless Chromium
# (Debian: apt-get install chromium-headless-shell). Not part of the tests.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
html="$root/docs/_build/html"
out="$root/docs/images/screenshots"
browser="$(command -v chromium-headless-shell || command -v chromium || true)"
[ -n "$browser" ] || { echo "docs_screenshots.sh: no headless Chromium (apt-get install chromium-headless-shell)" >&2; exit 2; }
[ -f "$html/index.html" ] || { echo "docs_screenshots.sh: build the docs first (bash scripts/docs.sh)" >&2; exit 2; }
mkdir -p "$out"
shot() {  # page, name, height
    "$browser" --no-sandbox --disable-gpu --window-size=1100,"$3" \
        --screenshot="$out/$2.png" "file://$html/$1" 2>/dev/null
    echo "$out/$2.png"
}
shot api/index.html api-index 900
shot api/generated/mitsweep.optics.pixels.html typed-signature 800
shot guide/weights.html equation-offline 900
