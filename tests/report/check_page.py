#!/usr/bin/env python3
"""Checks one rendered report page (tests/report/report_browser_test.sh):
console messages, self-containment, figure count and sizes in the DOM the
browser returned, labels inside their figure, every number a reader sees
rounded (no five decimals, no "-0"), the screenshot; and, asked for with
--expect, what the page must show:

  generating       the MTPA curve of the current plane reaches iq < 0 and
                   iq > 0 (read back through the y axis' own tick labels)
  dashed-labelled  every dashed or dotted table curve on the current plane
                   has a legend entry of the same pattern that says what it
                   means ("dashed: by symmetry ...", "dotted: extrapolated")
  extrapolated     ... and one of them is "dotted: extrapolated"
  envelope         the torque-speed envelope figure
  residual-maps    the diagnosis' residual maps (before, after) and spectrum
  spectrum-only    the spectrum, no residual maps, and the page says why

usage: check_page.py PAGE.html DOM.html CONSOLE.log REPORT.json SCREENSHOT.png [--expect KEY,...]
"""
import json, re, sys, os
from html.parser import HTMLParser

args = sys.argv[1:]
expect = set()
if "--expect" in args:
    i = args.index("--expect")
    expect = set(x for x in args[i + 1].split(",") if x)
    args = args[:i] + args[i + 2:]
html_path, dom_path, console_path, report_json, png = args
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


class Page(HTMLParser):
    """The DOM's figures (top-level <svg> in a <figure>; nested panel SVGs
    belong to theirs), each with its texts, y tick labels, line paths and
    legend entries, and the page's visible text."""

    def __init__(self):
        super().__init__()
        self.svgs = []        # dicts: id, width, height, texts, yticks, lines, legend
        self.depth = 0        # <svg> nesting
        self.cur = None
        self.groups = []      # classes of the open <g> elements
        self.text_attrs = None
        self.legend_line = None
        self.figures = 0
        self.skip = 0         # inside <style> / <script>
        self.visible = []

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag in ("style", "script"):
            self.skip += 1
        if tag == "figure":
            self.figures += 1
        if tag == "svg":
            self.depth += 1
            if self.depth == 1:
                self.cur = {"id": a.get("id", "?"), "width": a.get("width"), "height": a.get("height"),
                            "texts": [], "yticks": [], "lines": [], "legend": [], "ids": [a.get("id", "?")]}
                self.svgs.append(self.cur)
            elif self.cur is not None:
                self.cur["ids"].append(a.get("id", "?"))
        elif tag == "g":
            self.groups.append(a.get("class", ""))
        elif tag == "text" and self.cur is not None:
            self.text_attrs = a
        elif tag == "path" and self.cur is not None and a.get("class") == "line":
            self.cur["lines"].append(a)
        elif tag == "line" and self.cur is not None and "legend" in self.groups:
            self.legend_line = a

    def handle_startendtag(self, tag, attrs):
        self.handle_starttag(tag, attrs)
        if tag == "g":
            self.groups.pop()
        if tag == "svg":
            self.depth -= 1

    def handle_data(self, data):
        if self.skip == 0:
            self.visible.append(data)
        if self.text_attrs is not None and self.cur is not None:
            self.cur["texts"].append((self.text_attrs, data))
            if "yticks" in self.groups:
                self.cur["yticks"].append((float(self.text_attrs.get("y", 0)) - 4, data))
            if "legend" in self.groups:
                self.cur["legend"].append((self.legend_line, data))
                self.legend_line = None
            self.text_attrs = None

    def handle_endtag(self, tag):
        if tag in ("style", "script"):
            self.skip -= 1
        if tag == "svg":
            self.depth -= 1
            if self.depth == 0:
                self.cur = None
        if tag == "g" and self.groups:
            self.groups.pop()
        if tag == "text":
            self.text_attrs = None


p = Page()
dom = open(dom_path, errors="replace").read()
if "<body" not in dom:
    fail.append("the browser returned no DOM")
p.feed(dom)
if p.figures != rep["figures"] or len(p.svgs) != rep["figures"]:
    fail.append("rendered %d <figure> and %d <svg>, the command reported %d figures"
                % (p.figures, len(p.svgs), rep["figures"]))
for s in p.svgs:
    sid, w, h = s["id"], s["width"], s["height"]
    try:
        wf, hf = float(w), float(h)
    except (TypeError, ValueError):
        fail.append("%s: width/height missing (%r, %r)" % (sid, w, h)); continue
    if not (wf > 0 and hf > 0):
        fail.append("%s: zero size %r x %r" % (sid, w, h))
    # Nothing cut at the frame: every unrotated label inside the figure,
    # at the same conservative glyph width the plot module lays out with.
    # (Labels of nested panels are placed in their panel: not checked.)
    if len(s["ids"]) > 1:
        continue
    for a, t in s["texts"]:
        if "transform" in a:
            continue
        fs = float(a.get("font-size", 11))
        tw = 0.62 * fs * len(t)
        x, y = float(a.get("x", 0)), float(a.get("y", 0))
        anchor = a.get("text-anchor", "start")
        x0 = x - tw / 2 if anchor == "middle" else x - tw if anchor == "end" else x
        if x0 < -0.5 or x0 + tw > wf + 0.5 or y - fs < -0.5 or y > hf + 0.5:
            fail.append("%s: label %r at (%g, %g) runs past the %gx%g figure" % (sid, t, x, y, wf, hf))

# Every number a reader sees rounded to its meaning.
visible = " ".join(p.visible)
for m in re.finditer(r"\d\.\d{5,}", visible):
    fail.append("unrounded number %r in: ...%s..." % (m.group(0), visible[max(0, m.start() - 50):m.end() + 10]))
for m in re.finditer(r"(?:^|[^\w.])-0(?![\w.])", visible):
    fail.append("a '-0' in: ...%s..." % visible[max(0, m.start() - 50):m.end() + 10])

figs = {s["id"]: s for s in p.svgs}
all_ids = {i for s in p.svgs for i in s["ids"]}
MTPA, MTPV = "#d62728", "#1f77b4"


def points(d):
    nums = [float(x) for x in re.findall(r"-?\d+(?:\.\d+)?", d)]
    return list(zip(nums[0::2], nums[1::2]))


def y_of_pixel(svg):
    """Data value of a y pixel, from the axis' own tick labels."""
    ticks = [(py, float(t)) for py, t in svg["yticks"] if re.fullmatch(r"-?\d+(\.\d+)?", t.strip())]
    if len(ticks) < 2:
        return None
    (p0, v0), (p1, v1) = ticks[0], ticks[-1]
    return lambda py: v0 + (py - p0) * (v1 - v0) / (p1 - p0)


plane = figs.get("fig-plane")
if {"generating", "dashed-labelled", "extrapolated"} & expect and plane is None:
    fail.append("no current-plane figure (fig-plane)")
if "generating" in expect and plane is not None:
    to_iq = y_of_pixel(plane)
    iq = [to_iq(py) for l in plane["lines"] if l.get("stroke") == MTPA for _, py in points(l.get("d", ""))] \
        if to_iq else []
    if not iq or min(iq) > -0.5 or max(iq) < 0.5:
        fail.append("fig-plane: the MTPA curve does not reach both iq < 0 and iq > 0 (iq %s .. %s A)"
                    % (min(iq) if iq else "?", max(iq) if iq else "?"))
if {"dashed-labelled", "extrapolated"} & expect and plane is not None:
    patterns = {l.get("stroke-dasharray") for l in plane["lines"]
                if l.get("stroke") in (MTPA, MTPV) and l.get("stroke-dasharray")}
    keys = {(line or {}).get("stroke-dasharray"): text for line, text in plane["legend"]
            if text.startswith(("dotted:", "dashed:"))}
    if not patterns:
        fail.append("fig-plane: no dashed or dotted MTPA/MTPV stretch (nothing extrapolated or by symmetry drawn)")
    for pat in patterns:
        if pat not in keys:
            fail.append("fig-plane: curves dashed %r without a legend entry saying what that means" % pat)
    if "extrapolated" in expect and not any(t.startswith("dotted: extrapolated") for t in keys.values()):
        fail.append("fig-plane: no legend entry 'dotted: extrapolated'")
if "envelope" in expect and "fig-envelope-torque" not in figs:
    fail.append("no torque-speed envelope figure (fig-envelope-torque)")
if "residual-maps" in expect:
    for want in ("residual-before", "residual-after", "replay-spectrum"):
        if want not in all_ids:
            fail.append("diagnosis figure %s not embedded" % want)
if "spectrum-only" in expect:
    if "replay-spectrum" not in all_ids:
        fail.append("diagnosis spectrum (replay-spectrum) not embedded")
    if "residual-before" in all_ids:
        fail.append("residual maps embedded, but the document carries no residuals")
    if "Residual maps: not drawn" not in visible:
        fail.append("the page does not say why the residual maps are missing")

if not os.path.exists(png) or os.path.getsize(png) < 20000:
    fail.append("screenshot %s missing or nearly empty" % png)
if fail:
    print("\n".join(["FAIL " + html_path] + fail[:40]))
    sys.exit(1)
print("ok %s: %d figures rendered, all with non-zero size; checked %s; screenshot %s (%d bytes)"
      % (html_path, len(p.svgs), ",".join(sorted(expect)) or "the basics", png, os.path.getsize(png)))
