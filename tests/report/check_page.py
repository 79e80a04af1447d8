#!/usr/bin/env python3
"""Checks one rendered report page (tests/report/report_browser_test.sh):
console messages, self-containment, figure count and sizes in the DOM the
browser returned, labels inside their figure, the screenshot.

usage: check_page.py PAGE.html DOM.html CONSOLE.log REPORT.json SCREENSHOT.png
"""
import json, re, sys, os
from html.parser import HTMLParser
html_path, dom_path, console_path, report_json, png = sys.argv[1:]
fail = []
console = open(console_path, errors="replace").read()
for line in console.splitlines():
    # The page has no script, so any console message from it is a fault;
    # Chromium logs them all (console.error too) as "INFO:CONSOLE".
    if "CONSOLE" in line:
        fail.append("console message: " + line)
    if "Failed to load" in line or "net::ERR_" in line:
        fail.append("load error: " + line)
# Self-contained: no script, nothing loaded from elsewhere (only in-page
# url(#id) references, e.g. clip paths).
page = open(html_path, errors="replace").read()
if re.search(r"<script", page, re.I):
    fail.append("the page has a <script>")
for m in re.finditer(r'(?:src|href)\s*=\s*"([^"]*)"|url\(([^)]*)\)', page):
    ref = m.group(1) if m.group(1) is not None else m.group(2)
    if not ref.startswith("#"):
        fail.append("external reference: " + ref[:80])
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
