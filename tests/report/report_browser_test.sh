#!/usr/bin/env bash
# Browser test of `fluxcal report`: fits the public Baldor EOL set (real
# machine, hf_results + steady state) and a simulated set with a concealed
# dead time (diagnosed), writes one report page for each, opens them in
# headless Chromium and checks that they rendered: no console errors, every
# figure present in the rendered DOM with non-zero width and height, the
# figure count the command reported, and no SVG text running past its
# figure's edge. Screenshots stay in ARTEFACTS/ (a build artefact).
#
# usage: report_browser_test.sh FLUXCAL_BINARY ARTEFACTS_DIR SHARED_DIR
# FLUXCAL_NO_BROWSER=1 skips (exit 77, reported as skipped by ctest). A
# missing Chromium otherwise fails: CI installs it (scripts/install-deps.sh).
set -euo pipefail
F=$1
A=$2
SHARED=$3
if [ "${FLUXCAL_NO_BROWSER:-0}" = "1" ]; then
  echo "report_browser_test: skipped (FLUXCAL_NO_BROWSER=1)" >&2
  exit 77
fi
CHROME=""
for c in chromium chromium-browser google-chrome; do
  if command -v "$c" >/dev/null 2>&1; then CHROME=$(command -v "$c"); break; fi
done
if [ -z "$CHROME" ]; then
  echo "report_browser_test: FAIL: no chromium on PATH (scripts/install-deps.sh installs it; FLUXCAL_NO_BROWSER=1 skips)" >&2
  exit 1
fi
rm -rf "$A"
mkdir -p "$A"
W=$(mktemp -d)
trap 'rm -rf "$W"' EXIT

# Fixture 1: the real machine's EOL data (no waveforms: hf_results points).
"$F" fit "$SHARED/examples/real/baldor_eol" --out "$W/baldor.json" 2>"$W/fit_baldor.log" >/dev/null
"$F" report "$W/baldor.json" --set "$SHARED/examples/real/baldor_eol" --out "$A/baldor.html" --json \
  > "$W/baldor_report.json"

# Fixture 2: simulated EOL run with an uncompensated dead time, diagnosed.
"$F" simulate --serial IPM-REPORT-TEST --seed 7 --effects dead_time_s=2.5e-6 --out "$W/sim" 2>/dev/null >/dev/null
"$F" fit "$W/sim" --out "$W/sim.json" 2>/dev/null >/dev/null
"$F" diagnose "$W/sim" --json > "$W/diag.json" 2>/dev/null || true
"$F" report "$W/sim.json" --set "$W/sim" --diagnosis "$W/diag.json" --out "$A/sim.html" --json > "$W/sim_report.json"

# Bad input names the file and field.
echo '{"format": "something else"}' > "$W/bad_diag.json"
if "$F" report "$W/sim.json" --diagnosis "$W/bad_diag.json" --out "$W/x.html" 2> "$W/bad.err"; then
  echo "FAIL: a diagnosis document of the wrong format was accepted" >&2; exit 1
fi
grep -q "bad_diag.json: field 'format'" "$W/bad.err" || { echo "FAIL: error does not name file and field:"; cat "$W/bad.err"; exit 1; } >&2

for name in baldor sim; do
  html="$A/$name.html"
  # --dump-dom prints the DOM after layout; console messages go to stderr
  # with --enable-logging=stderr --v=0.
  timeout 60 "$CHROME" --headless --no-sandbox --disable-gpu --user-data-dir="$W/profile-$name" \
    --enable-logging=stderr --v=0 --dump-dom "file://$html" > "$W/$name.dom" 2> "$W/$name.console"
  timeout 60 "$CHROME" --headless --no-sandbox --disable-gpu --user-data-dir="$W/profile-$name" \
    --hide-scrollbars --window-size=1400,5200 --screenshot="$A/$name.png" "file://$html" \
    >/dev/null 2>> "$W/$name.console"
  cp "$W/$name.console" "$A/$name.console.log"
  python3 - "$html" "$W/$name.dom" "$W/$name.console" "$W/${name}_report.json" "$A/$name.png" <<'EOF'
import json, re, sys, os
from html.parser import HTMLParser
html_path, dom_path, console_path, report_json, png = sys.argv[1:]
fail = []
console = open(console_path, errors="replace").read()
for line in console.splitlines():
    # Console messages from the page: "CONSOLE(...)" / ":CONSOLE" lines.
    if "CONSOLE" in line and ("ERROR" in line or "error" in line.lower()):
        fail.append("console error: " + line)
    if "Failed to load" in line or "net::ERR_" in line:
        fail.append("load error: " + line)
rep = json.load(open(report_json))

class Svgs(HTMLParser):
    def __init__(self):
        super().__init__()
        self.svgs = []       # (id, width, height, [texts])
        self.cur = None
        self.text_attrs = None
        self.figures = 0
    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "figure":
            self.figures += 1
        if tag == "svg":
            self.cur = [a.get("id", "?"), a.get("width"), a.get("height"), []]
            self.svgs.append(self.cur)
        elif tag == "text" and self.cur is not None:
            self.text_attrs = a
    def handle_data(self, data):
        if self.text_attrs is not None and self.cur is not None:
            self.cur[3].append((self.text_attrs, data))
            self.text_attrs = None
    def handle_endtag(self, tag):
        if tag == "svg":
            self.cur = None
        if tag == "text":
            self.text_attrs = None

p = Svgs()
dom = open(dom_path, errors="replace").read()
if "<body" not in dom:
    fail.append("the browser returned no DOM")
p.feed(dom)
if p.figures != rep["figures"] or len(p.svgs) != rep["figures"]:
    fail.append("rendered %d <figure> and %d <svg>, the command reported %d figures"
                % (p.figures, len(p.svgs), rep["figures"]))
for sid, w, h, texts in p.svgs:
    try:
        wf, hf = float(w), float(h)
    except (TypeError, ValueError):
        fail.append("%s: width/height missing (%r, %r)" % (sid, w, h)); continue
    if not (wf > 0 and hf > 0):
        fail.append("%s: zero size %r x %r" % (sid, w, h))
    # Nothing cut at the frame: every unrotated label inside the figure,
    # at the same conservative glyph width the plot module lays out with.
    for a, t in texts:
        if "transform" in a:
            continue
        fs = float(a.get("font-size", 11))
        tw = 0.62 * fs * len(t)
        x, y = float(a.get("x", 0)), float(a.get("y", 0))
        anchor = a.get("text-anchor", "start")
        x0 = x - tw / 2 if anchor == "middle" else x - tw if anchor == "end" else x
        if x0 < -0.5 or x0 + tw > wf + 0.5 or y - fs < -0.5 or y > hf + 0.5:
            fail.append("%s: label %r at (%g, %g) runs past the %gx%g figure" % (sid, t, x, y, wf, hf))
if not os.path.exists(png) or os.path.getsize(png) < 20000:
    fail.append("screenshot %s missing or nearly empty" % png)
if fail:
    print("\n".join(["FAIL " + html_path] + fail[:40]))
    sys.exit(1)
print("ok %s: %d figures rendered, all with non-zero size; screenshot %s (%d bytes)"
      % (html_path, len(p.svgs), png, os.path.getsize(png)))
EOF
done
grep -q '"verdict"' "$W/sim_report.json"
grep -q "Diagnosis" "$A/sim.html" || { echo "FAIL: diagnosis section missing from sim.html" >&2; exit 1; }
echo "report_browser_test: ok (artefacts in $A)"
