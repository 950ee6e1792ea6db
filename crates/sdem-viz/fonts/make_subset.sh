#!/usr/bin/env bash
# Makes NotoSans-Regular-subset.ttf, the font sdem's pictures are drawn with, from Debian's
# fonts-noto-core package (Noto Sans 2.004, SIL Open Font License 1.1, no Reserved Font Name).
# Run once, in this folder; the result is committed. Needs apt-get and Python 3.
set -euo pipefail
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
(cd "$work" && apt-get download fonts-noto-core=20201225-1 && dpkg-deb -x fonts-noto-core_*.deb x)
python3 -m venv "$work/venv"
"$work/venv/bin/pip" install --quiet fonttools==4.61.1
# Basic Latin, Latin-1, Greek, dashes, quotes and ellipsis, superscripts (Noto Sans has no arrows
# or math signs such as ≤; text.rs draws what the font lacks as ?).
"$work/venv/bin/pyftsubset" "$work/x/usr/share/fonts/truetype/noto/NotoSans-Regular.ttf" \
  --unicodes="U+0020-007E,U+00A0-00FF,U+0391-03A9,U+03B1-03C9,U+2010-2027,U+2030-2033,U+2070-2079,U+207B" \
  --no-hinting --desubroutinize --layout-features='' --output-file=NotoSans-Regular-subset.ttf
ls -l NotoSans-Regular-subset.ttf
