#!/usr/bin/env bash
# The README's first command: the main job end to end on the embedded
# default (SQLite). Builds the `fluxcal` binary (reusing a build that
# exists; configuring, after installing missing Debian packages, only when
# there is none or it belongs to another path: scripts/configure.sh),
# starts the service on a SQLite file, simulates EOL runs of several
# serials with production spread, streams them, fits, exports tables in
# every format, runs engineer queries, diagnoses a run, writes one report
# page per serial and an index linking them (out/demo/index.html), prints
# where every output is, stops the service.
#   OUT (default out/demo; replaced on every run), PORT (default a free
#   loopback port), SERIALS (default 6), BUILD_DIR (default build).
set -euo pipefail
cd "$(dirname "$0")/.."
OUT=${OUT:-out/demo}
SERIALS=${SERIALS:-6}
BUILD_DIR=${BUILD_DIR:-build}
export BUILD_DIR

step() { printf '\n== %s\n' "$*" >&2; }

step "build $BUILD_DIR/cli/fluxcal (reused if built; configured only if needed)"
bash scripts/configure.sh
cmake --build "$BUILD_DIR" --target fluxcal >&2
F=$(cd "$BUILD_DIR" && pwd -P)/cli/fluxcal
"$F" --version >&2
# A port the kernel hands out (bind to 0) unless PORT is given: a second
# demo, or anything else on a fixed port, does not collide with this one.
PORT=${PORT:-$(python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1]); s.close()')}

rm -rf "$OUT"
mkdir -p "$OUT/sets" "$OUT/tables" "$OUT/queries" "$OUT/plots"
step "start the calibration service on $OUT/fluxcal.db (127.0.0.1:$PORT)"
"$F" serve --db "$OUT/fluxcal.db" --listen "127.0.0.1:$PORT" 2> "$OUT/serve.log" &
SERVER=$!
trap 'kill $SERVER 2>/dev/null || true; wait $SERVER 2>/dev/null || true' EXIT
up=0
for _ in $(seq 50); do
  "$F" list --server "127.0.0.1:$PORT" >/dev/null 2>&1 && { up=1; break; }
  kill -0 "$SERVER" 2>/dev/null || break
  sleep 0.2
done
if [ "$up" != 1 ]; then
  echo "demo: the service did not start on 127.0.0.1:$PORT; its log ($OUT/serve.log):" >&2
  cat "$OUT/serve.log" >&2
  exit 1
fi

step "simulate $SERIALS EOL runs with the digital twin (production spread; the last one with an uncompensated dead time)"
for i in $(seq 1 "$SERIALS"); do
  serial=$(printf 'IPM-DEMO-%04d' "$i")
  effects=""
  [ "$i" -eq "$SERIALS" ] && effects="dead_time_s=2.5e-6"
  "$F" simulate --serial "$serial" --seed "$i" --spread ${effects:+--effects $effects} \
    --out "$OUT/sets/$serial" 2>&1 | tail -n 1 >&2
done

step "EOL flow per serial: identify locally, stream to the service, fit, verdict, fetch tables"
for set in "$OUT"/sets/*/; do
  set=${set%/}
  "$F" eol "$set" --server "127.0.0.1:$PORT" --station demo-eol-1 --tables-dir "$OUT/tables" \
    --json > "$OUT/queries/eol_$(basename "$set").json" || true
  python3 -c "import json,sys; d=json.load(open(sys.argv[1])); print('  %s v%d %-9s %s' % (d['serial'], d['version'], d['model'], d['verdict']))" \
    "$OUT/queries/eol_$(basename "$set").json" >&2
done

first=IPM-DEMO-0001
step "flashing station: every table in every format for $first"
# The drive's DC-link voltage, as the station knows it (the set's manifest,
# drive.udc_v): a run of HF points does not carry it into the store, and
# mtpv and fw tables are computed for a voltage limit (docs/cli.md, Machine facts).
udc=$(python3 -c 'import json, sys; print(json.load(open(sys.argv[1]))["drive"]["udc_v"])' "$OUT/sets/$first/manifest.json")
for table in mtpa mtpv fw; do
  limits=()
  [ "$table" != mtpa ] && limits=(--udc-v "$udc")
  for fmt in csv json h cdfx dcm; do
    "$F" export "$first" --server "127.0.0.1:$PORT" --table "$table" --format "$fmt" "${limits[@]}" \
      --out "$OUT/tables/${first}_${table}.${fmt}" >&2
  done
done

step "engineer queries"
"$F" list --server "127.0.0.1:$PORT" | tee "$OUT/queries/list.txt" >&2
"$F" history "$first" --server "127.0.0.1:$PORT" --json > "$OUT/queries/history_$first.json"
"$F" query "$first" --server "127.0.0.1:$PORT" --id-a -20 --iq-a 40 | tee "$OUT/queries/query_$first.txt" >&2
"$F" fleet --server "127.0.0.1:$PORT" | tee "$OUT/queries/fleet.txt" >&2

step "local tools: identify, fit, query grid and plots on $first"
"$F" identify "$OUT/sets/$first" --csv > "$OUT/queries/identify_$first.csv" 2>/dev/null
"$F" fit "$OUT/sets/$first" --out "$OUT/calibration_$first.json" 2>/dev/null >&2
"$F" query "$OUT/calibration_$first.json" --grid -100:0:11,0:100:11 > "$OUT/queries/grid_$first.csv"
"$F" export "$OUT/calibration_$first.json" --table mtpa --format csv --out "$OUT/tables/local_mtpa.csv" \
  --svg "$OUT/plots/${first}_mtpa_mtpv.svg" >&2
"$F" export "$OUT/calibration_$first.json" --table fw --format csv --out "$OUT/tables/local_fw.csv" \
  --svg "$OUT/plots/${first}_fw_id.svg" >&2

last=$(printf 'IPM-DEMO-%04d' "$SERIALS")
# grep reads all of the help text: with -q it would stop at the first match,
# `fluxcal help` would die of SIGPIPE, and pipefail would skip this step.
if "$F" help 2>&1 | grep diagnose >/dev/null; then
  step "diagnosis of $last (the twin concealed a dead time in it)"
  "$F" diagnose "$OUT/sets/$last" --plots "$OUT/plots/diagnosis_$last" > "$OUT/diagnosis_$last.txt" || true
  "$F" diagnose "$OUT/sets/$last" --json > "$OUT/diagnosis_$last.json" || true
  cat "$OUT/diagnosis_$last.txt" >&2
fi

step "one report page per serial (identity, fit, surfaces, limits, tables; diagnosis for $last)"
mkdir -p "$OUT/reports"
for set in "$OUT"/sets/*/; do
  set=${set%/}
  serial=$(basename "$set")
  diag=()
  [ -s "$OUT/diagnosis_$serial.json" ] && diag=(--diagnosis "$OUT/diagnosis_$serial.json")
  "$F" report "$serial" --server "127.0.0.1:$PORT" --set "$set" "${diag[@]}" \
    --out "$OUT/reports/$serial.html" --json > "$OUT/queries/report_$serial.json" 2>/dev/null
done
# The index: one row per serial from the reports' own --json summaries.
python3 - "$OUT" <<'PY' >&2
import html, json, os, sys
out = sys.argv[1]
rows = []
for name in sorted(os.listdir(os.path.join(out, "queries"))):
    if not (name.startswith("report_") and name.endswith(".json")):
        continue
    r = json.load(open(os.path.join(out, "queries", name)))
    link = os.path.relpath(r["out"], out)
    cls = "pass" if r["verdict"] == "pass" else "fail"
    rows.append('<tr><td><a href="%s">%s</a></td><td>%d</td><td class="%s">%s</td><td>%d</td></tr>'
                % (html.escape(link), html.escape(r["serial"]), r["version"], cls, html.escape(r["verdict"]), r["figures"]))
page = ('<!DOCTYPE html><html lang="en"><head><meta charset="utf-8"><title>fluxcal demo reports</title>\n'
        '<style>body{font-family:sans-serif;margin:24px} td,th{padding:4px 10px;text-align:left;'
        'border-bottom:1px solid #ddd} .pass{color:#2a7d2a;font-weight:bold} .fail{color:#b02a2a;font-weight:bold}'
        '</style></head><body>\n<h1>fluxcal demo: one calibration report per serial</h1>\n'
        '<table><tr><th>serial</th><th>version</th><th>verdict</th><th>figures</th></tr>\n'
        + "\n".join(rows) + '\n</table></body></html>\n')
open(os.path.join(out, "index.html"), "w").write(page)
print("  index: %s (%d reports)" % (os.path.join(out, "index.html"), len(rows)))
PY

step "summary"
cat >&2 <<SUMMARY
  binary:         $F (fluxcal help lists the commands)
  store:          $OUT/fluxcal.db (SQLite, WAL)   service log: $OUT/serve.log
  recording sets: $OUT/sets/ (truth files beside them: $OUT/sets/*.truth.json)
  EOL results:    $OUT/queries/eol_*.json
  ECU tables:     $OUT/tables/ ($(ls "$OUT/tables" | wc -l) files: CSV, JSON, C header, CDFX, DCM)
  queries:        $OUT/queries/ (list, history, query, fleet, identify, grid)
  calibration:    $OUT/calibration_$first.json
  plots:          $OUT/plots/
  diagnosis:      $OUT/diagnosis_$last.txt / .json (if diagnosis is built)
  report pages:   $OUT/index.html -> $OUT/reports/<serial>.html
SUMMARY
