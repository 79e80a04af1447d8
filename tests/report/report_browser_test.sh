#!/usr/bin/env bash
# Browser test of `fluxcal report`: fits the public Baldor EOL set (real
# machine measured in the motoring half only, hf_results + steady state;
# data/real/baldor_eol) and a simulated set with a concealed dead time
# (diagnosed by the report itself, and from a diagnosis document), and a
# fit of the Baldor's measured flux map with its nodes drawn; writes one
# report page for each, opens them in headless Chromium and checks
# (check_page.py) that they rendered: no console errors, every figure
# present in the rendered DOM with non-zero width and height, the figure
# count the command reported, no SVG text running past its figure's edge,
# no unrounded number and no "-0" in the visible text; and what each page
# must show: the generating half of the current plane, dashed and dotted
# curves with their legend entries (extrapolated, by symmetry), the
# envelope, the diagnosis' residual maps when the report ran the diagnosis
# and only its spectrum from a document. Screenshots stay in ARTEFACTS/
# (a build artefact).
#
# usage: report_browser_test.sh FLUXCAL_BINARY ARTEFACTS_DIR DATA_DIR
# FLUXCAL_NO_BROWSER=1 skips (exit 77, reported as skipped by ctest). A
# missing Chromium otherwise fails: CI installs it (scripts/install-deps.sh).
set -euo pipefail
F=$1
A=$2
DATA=$3
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
HERE=$(cd "$(dirname "$0")" && pwd)
rm -rf "$A"
mkdir -p "$A"
W=$(mktemp -d)
trap 'rm -rf "$W"' EXIT

# Fixture 1: the real machine's EOL data (no waveforms: hf_results points),
# measured for iq >= 0 only; its model (smooth-asym) is not symmetric in iq,
# so the generating half the tables use is extrapolated.
"$F" fit "$DATA/real/baldor_eol" --out "$W/baldor.json" 2>"$W/fit_baldor.log" >/dev/null
"$F" report "$W/baldor.json" --set "$DATA/real/baldor_eol" --out "$A/baldor.html" --json \
  > "$W/baldor_report.json"
EXPECT_baldor="generating,dashed-labelled,extrapolated,envelope"

# Fixture 2: simulated EOL run with an uncompensated dead time; the report
# runs the diagnosis (residual maps and spectrum embedded), and a second
# page takes the diagnosis document (spectrum only, and it says why).
"$F" simulate --serial IPM-REPORT-TEST --seed 7 --effects dead_time_s=2.5e-6 --out "$W/sim" 2>/dev/null >/dev/null
"$F" fit "$W/sim" --out "$W/sim.json" 2>/dev/null >/dev/null
"$F" report "$W/sim.json" --set "$W/sim" --diagnose --out "$A/sim.html" --json > "$W/sim_report.json"
EXPECT_sim="generating,dashed-labelled,envelope,residual-maps"
"$F" diagnose "$W/sim" --json > "$W/diag.json" 2>/dev/null || true
"$F" report "$W/sim.json" --diagnosis "$W/diag.json" --out "$A/sim_doc.html" --json > "$W/sim_doc_report.json"
EXPECT_sim_doc="generating,spectrum-only"

# Fixture 3: the measured flux map of the same machine (both torque
# directions), fitted, its nodes over the surfaces; the map-fit row.
"$F" fit --map "$DATA/real/baldor_fluxmap_measured.csv" --pole-pairs 2 --rs-ohm 3.6 --udc-v 540 --serial BALDOR-MAP \
  --out "$W/map.json" 2>/dev/null >/dev/null
"$F" report "$W/map.json" --map "$DATA/real/baldor_fluxmap_measured.csv" --out "$A/map.html" --json \
  > "$W/map_report.json"
EXPECT_map="generating,envelope"
for want in "<th>flux error against the map</th><td>RMS " "flux map nodes" "Both halves measured"; do
  grep -qF "$want" "$A/map.html" || { echo "FAIL: map.html lacks '$want'" >&2; exit 1; }
done

# From the service: the page its GetReport builds for the stored version,
# with the store's provenance (version, creation time, stored verdict,
# release state) and the fleet. A port the
# kernel just handed out (bind to 0), not one derived from the process id:
# two tests must not meet on one port.
PORT=$(python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1]); s.close()')
"$F" serve --db "$W/store.db" --listen "127.0.0.1:$PORT" --quiet 2> "$W/serve.log" &
SERVER=$!
trap 'kill $SERVER 2>/dev/null || true; wait $SERVER 2>/dev/null || true; rm -rf "$W"' EXIT
for _ in $(seq 50); do
  "$F" list --server "127.0.0.1:$PORT" >/dev/null 2>&1 && break
  sleep 0.2
done
# eol exits 1 on a failing verdict (this set's dead time fails the fit);
# what matters here is that it stored version 1.
"$F" eol "$W/sim" --server "127.0.0.1:$PORT" --json > "$W/eol.json" 2>/dev/null || true
grep -q '"version": 1' "$W/eol.json" || { echo "FAIL: eol stored no calibration:" >&2; cat "$W/eol.json" >&2; exit 1; }
"$F" report IPM-REPORT-TEST --server "127.0.0.1:$PORT" --out "$A/service.html" --json > "$W/service_report.json"
for want in "calibration version</th><td>1</td>" "release state</th><td>not released" "calibration created</th><td>20" "from the service's store" "<h2>Fleet</h2>" "IPM-REPORT-TEST"; do
  grep -qF "$want" "$A/service.html" || { echo "FAIL: service.html lacks '$want'" >&2; exit 1; }
done
# The EOL flow with the raw recording uploaded, then the service's own
# diagnosis stores the diagnosed model as a new version (the set's dead
# time failed the plain fit; the diagnosed model is judged again).
"$F" eol "$W/sim" --server "127.0.0.1:$PORT" --upload-recording --json > "$W/eol2.json" 2>/dev/null || true
"$F" diagnose IPM-REPORT-TEST --server "127.0.0.1:$PORT" --store --json > "$W/rdiag.json"
python3 - "$W/rdiag.json" <<'PY' || exit 1
import json, sys
d = json.load(open(sys.argv[1]))
names = [f.get("effect") for f in d.get("findings", [])]
if "dead_time" not in names or d.get("stored", {}).get("version", 0) < 2:
    sys.exit(f"FAIL: remote diagnose --store: findings {names}, stored {d.get('stored')}")
PY
# The diagnosed version's page carries the findings it was stored with.
"$F" report IPM-REPORT-TEST --server "127.0.0.1:$PORT" --out "$A/service_diagnosed.html" --json \
  > "$W/service_diagnosed_report.json"
for want in "<h2>Diagnosis</h2>" "<td>dead_time</td>" "from the service's store"; do
  grep -qF "$want" "$A/service_diagnosed.html" || { echo "FAIL: service_diagnosed.html lacks '$want'" >&2; exit 1; }
done
kill $SERVER; wait $SERVER 2>/dev/null || true

# Bad input names the file and field.
echo '{"format": "something else"}' > "$W/bad_diag.json"
if "$F" report "$W/sim.json" --diagnosis "$W/bad_diag.json" --out "$W/x.html" 2> "$W/bad.err"; then
  echo "FAIL: a diagnosis document of the wrong format was accepted" >&2; exit 1
fi
grep -q "bad_diag.json: field 'format'" "$W/bad.err" || { echo "FAIL: error does not name file and field:"; cat "$W/bad.err"; exit 1; } >&2

EXPECT_service="generating"
EXPECT_service_diagnosed="generating"
for name in baldor sim sim_doc map service service_diagnosed; do
  html="$A/$name.html"
  # --dump-dom prints the DOM after layout; console messages go to stderr
  # with --enable-logging=stderr --v=0.
  timeout 60 "$CHROME" --headless --no-sandbox --disable-gpu --user-data-dir="$W/profile-$name" \
    --enable-logging=stderr --v=0 --dump-dom "file://$html" > "$W/$name.dom" 2> "$W/$name.console"
  timeout 60 "$CHROME" --headless --no-sandbox --disable-gpu --user-data-dir="$W/profile-$name" \
    --hide-scrollbars --window-size=1400,5200 --screenshot="$A/$name.png" "file://$html" \
    >/dev/null 2>> "$W/$name.console"
  cp "$W/$name.console" "$A/$name.console.log"
  expect_var="EXPECT_$name"
  python3 "$HERE/check_page.py" "$html" "$W/$name.dom" "$W/$name.console" "$W/${name}_report.json" "$A/$name.png" \
    --expect "${!expect_var}"
done
# The checker must catch what it is for: a page with a console error, an
# external image, a zero-size figure, a label past the edge, unrounded
# numbers and a "-0", a current plane whose MTPA stays in the motoring half
# and whose dotted MTPV has no legend entry, no envelope, no residual maps.
cat > "$W/bad.html" <<'HTML'
<!DOCTYPE html><html><body><figure><svg id="z" width="100" height="0"><text x="90" y="10">far too long</text></svg></figure>
<figure><svg id="fig-plane" width="300" height="300"><g class="yticks"><text x="20" y="204">0</text><text x="20" y="104">10</text></g>
<path class="line" d="M50 200 L60 150 L70 100" stroke="#d62728"/>
<path class="line" d="M50 150 L60 140" stroke="#1f77b4" stroke-dasharray="2 3"/>
<g class="legend"><line x1="200" y1="20" x2="224" y2="20" stroke="#1f77b4"/><text x="230" y="24">MTPV</text></g></svg></figure>
<p>psi_pm 0.446782133 Wb, measured region id -18 .. -0 A</p>
<img src="elsewhere.png"><script>console.error("boom")</script></body></html>
HTML
echo '{"figures": 2}' > "$W/bad_report.json"
timeout 60 "$CHROME" --headless --no-sandbox --disable-gpu --user-data-dir="$W/profile-bad" \
  --enable-logging=stderr --v=0 --dump-dom "file://$W/bad.html" > "$W/bad.dom" 2> "$W/bad.console"
if python3 "$HERE/check_page.py" "$W/bad.html" "$W/bad.dom" "$W/bad.console" "$W/bad_report.json" "$W/none.png" \
     --expect generating,dashed-labelled,extrapolated,envelope,residual-maps > "$W/bad.check"; then
  echo "FAIL: the page checker passed a broken page" >&2; exit 1
fi
for what in "console message" "external reference" "zero size" "runs past" "<script>" "unrounded number '0.446782133'" \
            "a '-0'" "does not reach both iq < 0 and iq > 0" "dashed '2 3' without a legend entry" \
            "no legend entry 'dotted: extrapolated'" "no torque-speed envelope" "residual-before not embedded"; do
  grep -q "$what" "$W/bad.check" || { echo "FAIL: the page checker missed: $what" >&2; cat "$W/bad.check" >&2; exit 1; }
done

grep -q '"verdict"' "$W/sim_report.json"
grep -q "Diagnosis" "$A/sim.html" || { echo "FAIL: diagnosis section missing from sim.html" >&2; exit 1; }
grep -qF "computed by this report from the recording set" "$A/sim.html" || \
  { echo "FAIL: sim.html does not say where its residual maps come from" >&2; exit 1; }
echo "report_browser_test: ok (artefacts in $A)"
