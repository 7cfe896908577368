#!/usr/bin/env python3
"""Acceptance test of the 3D view of report.html and verify.html (issue 18) in headless Chromium, standard library only.

Runs `flankcam run JOB --out WORK/run`, then for two states of the view (the first pose, and the
slider moved through the URL hash #track=K&pose=N the page honours):
  * --dump-dom: <body data-flankcam-viewer="ready">, the readout names the pose, and Chromium's
    log has no console message (the page's own hooks turn errors into data-flankcam-viewer="error: ...");
  * --screenshot: the canvas shows the deviation bands (green "within tolerance" pixels), and moving
    the slider moved the tool (the pictures differ inside the canvas).
Then the same job at a tolerance of 1 um, where every patch gouges: the page is ready and #marker=M
jumps to the worst pose of that gouge.
verify.html (the same viewer over what `flankcam verify` simulated): `flankcam verify` of the run's
programs (one dialect, each program and the whole run); the same two states (ready, no console
message, deviation bands on the canvas, the slider moves the tool, the readout names the program
line); then a copy of a program with one cutting block moved 1 mm sideways into the blade (exit 4):
its marker is labelled with that line and #marker=0 jumps to the hit's deepest simulated position;
the machine mode (#machine=1) turns the tables and puts the tip where the program's joints say.
Without a browser it exits 77 (CTest: skipped) unless FLANKCAM_REQUIRE_BROWSER=1, then it fails.
--save PATH keeps the second screenshot (the README's picture: examples/conical-tool/report-view.png);
--save-verify PATH the marker jump of verify.html (examples/conical-tool/verify-view.png).
"""
import json
import argparse
import base64
import concurrent.futures
import os
import re
import shutil
import struct
import subprocess
import sys
import tempfile
import zlib

WINDOW = (1280, 760)
CANVAS_HEIGHT = 640  # #fcv-canvas in view=only mode starts at the top


def find_browser():
    for name in [os.environ.get("FLANKCAM_CHROMIUM", ""), "chromium", "chromium-browser", "google-chrome"]:
        if name and shutil.which(name):
            return shutil.which(name)
    return None


def read_png(path):
    """(width, height, rows of RGB tuples) of an 8-bit, non-interlaced RGB or RGBA PNG."""
    data = open(path, "rb").read()
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        raise ValueError(f"{path}: not a PNG")
    pos, idat, width = 8, b"", 0
    while pos < len(data):
        length, kind = struct.unpack(">I4s", data[pos:pos + 8])
        body = data[pos + 8:pos + 8 + length]
        if kind == b"IHDR":
            width, height, depth, colour, _, _, interlace = struct.unpack(">IIBBBBB", body)
            if depth != 8 or colour not in (2, 6) or interlace:
                raise ValueError(f"{path}: unsupported PNG (depth {depth}, colour type {colour}, interlace {interlace})")
            bpp = 3 if colour == 2 else 4
        elif kind == b"IDAT":
            idat += body
        pos += 12 + length
    raw = zlib.decompress(idat)
    stride = width * bpp
    rows, prev = [], bytearray(stride)
    for y in range(height):
        f = raw[y * (stride + 1)]
        line = bytearray(raw[y * (stride + 1) + 1:(y + 1) * (stride + 1)])
        for i in range(stride):
            a = line[i - bpp] if i >= bpp else 0
            b = prev[i]
            c = prev[i - bpp] if i >= bpp else 0
            if f == 1:
                line[i] = (line[i] + a) & 255
            elif f == 2:
                line[i] = (line[i] + b) & 255
            elif f == 3:
                line[i] = (line[i] + (a + b) // 2) & 255
            elif f == 4:
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                line[i] = (line[i] + (a if pa <= pb and pa <= pc else b if pb <= pc else c)) & 255
        rows.append([tuple(line[x * bpp:x * bpp + 3]) for x in range(width)])
        prev = line
    return width, height, rows


def band(rgb):
    """The deviation band a lit pixel shows: within (green), under (red), over (blue), or None."""
    r, g, b = rgb
    if g > 60 and g > 1.5 * r and g > 1.3 * b:
        return "within"
    if r > 80 and r > 2.5 * g and r > 2.5 * b:
        return "under"
    if b > 80 and b > 2.2 * r and b > 1.6 * g:
        return "over"
    return None


class Browser:
    def __init__(self, exe, work):
        self.exe, self.work = exe, work

    def run(self, url, *flags):
        profile = tempfile.mkdtemp(prefix="profile-", dir=self.work)
        cmd = [self.exe, "--headless", "--no-sandbox", "--disable-gpu", "--use-angle=swiftshader",
               "--enable-unsafe-swiftshader", "--hide-scrollbars", "--no-first-run", "--disable-extensions",
               f"--user-data-dir={profile}", f"--window-size={WINDOW[0]},{WINDOW[1]}", "--virtual-time-budget=15000",
               "--enable-logging=stderr", "--v=0", *flags, url]
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=240)
        shutil.rmtree(profile, ignore_errors=True)
        return p

    def dom(self, url):
        p = self.run(url, "--dump-dom")
        # Chromium logs every console message of the page as INFO:CONSOLE; SwiftShader's performance
        # notes about ReadPixels (the screenshot) are the driver's, not the page's.
        console = [l for l in p.stderr.splitlines() if ":CONSOLE" in l and "GL Driver Message (OpenGL, Performance" not in l]
        return p.stdout, console

    def screenshot(self, url, path):
        self.run(url, f"--screenshot={path}")
        if not os.path.exists(path):
            raise RuntimeError(f"chromium wrote no screenshot for {url}")
        return read_png(path)


def check_state(browser, page, fragment, png, failures):
    url = "file://" + page + fragment
    # The DOM and the screenshot from two Chromium processes at once (each mostly waits).
    with concurrent.futures.ThreadPoolExecutor(max_workers=2) as pool:
        shot = pool.submit(browser.screenshot, url, png)
        dom, console = browser.dom(url)
        width, height, rows = shot.result()
    state = re.search(r'<body[^>]*data-flankcam-viewer="([^"]*)"', dom)
    label = re.search(r'<span id="fcv-frame">([^<]*)</span>', dom)
    print(f"{fragment}: data-flankcam-viewer={state.group(1) if state else None!r}, "
          f"{label.group(1) if label else 'no pose label'}, {len(console)} console message(s)")
    if not state or state.group(1) != "ready":
        failures.append(f"{fragment}: data-flankcam-viewer is {state.group(1) if state else 'missing'!r}, not 'ready'")
    for line in console:
        failures.append(f"{fragment}: console: {line}")
    counts = {"within": 0, "under": 0, "over": 0}
    canvas = rows[:min(height, CANVAS_HEIGHT)]
    for row in canvas:
        for px in row:
            k = band(px)
            if k:
                counts[k] += 1
    share = counts["within"] / (width * len(canvas))
    print(f"{fragment}: canvas {width}x{len(canvas)}: within {counts['within']}, under {counts['under']}, "
          f"over {counts['over']} pixels ({100 * share:.1f}% green)")
    if share < 0.01:
        failures.append(f"{fragment}: the canvas shows no deviation bands ({counts['within']} green pixels)")
    return label.group(1) if label else None, canvas, dom


def view_data(page):
    """The view's JSON embedded in a page."""
    html = open(page, encoding="utf-8").read()
    m = re.search(r'<script type="application/json" id="fcv-data">(.*?)</script>', html, re.S)
    return json.loads(m.group(1)) if m else None


def marker_pixels(rows):
    """Pixels of the collision markers' colour (#ff2060, unlit), the legend's dot (top right) left out."""
    width = len(rows[0]) if rows else 0
    return sum(1 for y, row in enumerate(rows) for x, (r, g, b) in enumerate(row)
               if r > 225 and g < 70 and 60 < b < 130 and not (y < 110 and x >= width - 290))


PROGRAM_EXTENSIONS = [".ngc", ".nc", ".mpf", ".h"]  # verify one dialect: the first of these the run wrote


def check_verify(browser, a, work, run_dir):
    """verify.html of the run's programs, then of a program with one cutting block moved into the blade."""
    failures = []
    names = sorted(os.listdir(run_dir))
    ext = next((e for e in PROGRAM_EXTENSIONS if any(n.endswith(e) for n in names)), None)
    programs = [os.path.join(run_dir, n) for n in names if ext and n.endswith(ext)]
    if not programs:
        return ["the run wrote no program to verify"]
    out = os.path.join(work, "verify")
    p = subprocess.run([a.flankcam, "verify", "--job", a.job, *programs, "--out", out], capture_output=True, text=True)
    if p.returncode != 0:
        return [f"flankcam verify of the run's {len(programs)} program(s) exited {p.returncode}: {p.stderr.strip()}"]
    page = os.path.join(out, "verify.html")
    html = open(page, encoding="utf-8").read()
    print(f"verify.html of {len(programs)} program(s): {len(html) / 1e6:.2f} MB")
    if re.search(r'<script[^>]+src=|<link[^>]+href="?https?:|https?://[^"\s]*\.js', html):
        failures.append("verify.html loads something from outside the page")
    data = view_data(page)
    report = json.load(open(os.path.join(out, "verify.json"), encoding="utf-8"))
    if not data:
        return failures + ["verify.html has no 3D view data"]
    # One track per program (all its simulated positions) and one of the whole run.
    simulated = [int(q["positions_simulated"]) for q in report["programs"]]
    tracks = [t["original_frames"] for t in data["tracks"]]
    expected = simulated + ([sum(simulated)] if len(simulated) > 1 else [])
    print(f"verify view: tracks of {tracks} positions, verify simulated {simulated}")
    if tracks != expected:
        failures.append(f"the verify view's tracks have {tracks} positions, verify simulated {expected}")
    # The whole run (the last track), slider at the feed block nearest half way: the tool at the blade.
    track = len(data["tracks"]) - 1
    rapid = base64.b64decode(data["tracks"][track]["rapid"])
    half = len(rapid) // 2
    pose = min((i for i in range(len(rapid)) if not rapid[i]), key=lambda i: abs(i - half), default=half)
    first_label, first, _ = check_state(browser, page, "#view=only", os.path.join(work, "verify-first.png"), failures)
    moved_label, moved, moved_dom = check_state(browser, page, f"#view=only&track={track}&pose={pose}",
                                                os.path.join(work, "verify-moved.png"), failures)
    if moved_label != f"pose {pose + 1} / {data['tracks'][track]['frames']}":
        failures.append(f"verify.html after moving the slider says {moved_label!r}")
    changed = sum(1 for r0, r1 in zip(first, moved) for p0, p1 in zip(r0, r1) if p0 != p1)
    print(f"verify.html: pixels changed by moving the slider: {changed}")
    if changed < 1000:
        failures.append(f"verify.html: moving the slider changed only {changed} pixels of the canvas")
    readout = re.search(r'<div id="fcv-readout">([^<]*)</div>', moved_dom)
    print(f"verify.html readout: {readout.group(1) if readout else None!r}")
    if not readout or not re.search(r"\bline \d+\b.*programmed X -?\d", readout.group(1)):
        failures.append(f"verify.html's readout names no program line and axis values: {readout.group(1) if readout else None!r}")
    failures += check_machine(browser, page, data, work, moved)
    return failures + check_verify_collision(browser, a, work, programs[0])


def check_machine(browser, page, data, work, part_frame):
    """Machine mode (#machine=1) at the same pose as `part_frame` (the whole-run slider state): the
    tables turn the part, the picture changes, the bands stay on the canvas; on a table-table machine
    programmed with joint values (the conical-tool job's xyzac-trt) the tool tip the view computes
    through the machine's chain is where the program's X Y Z put it."""
    if not data.get("machine"):
        return ["verify.html has no machine for its machine mode"]
    track = len(data["tracks"]) - 1
    rapid = base64.b64decode(data["tracks"][track]["rapid"])
    half = len(rapid) // 2
    pose = min((i for i in range(len(rapid)) if not rapid[i]), key=lambda i: abs(i - half), default=half)
    fragment = f"#view=only&track={track}&pose={pose}&machine=1"
    failures = []
    _, canvas, dom = check_state(browser, page, fragment, os.path.join(work, "verify-machine.png"), failures)
    changed = sum(1 for r0, r1 in zip(part_frame, canvas) for p0, p1 in zip(r0, r1) if p0 != p1)
    print(f"{fragment}: pixels changed by the machine mode: {changed}")
    if changed < 1000:
        failures.append(f"the machine mode changed only {changed} pixels")
    readout = re.search(r'<div id="fcv-readout">([^<]*)</div>', dom)
    text = readout.group(1) if readout else ""
    print(f"{fragment}: readout {text!r}")
    programmed = re.search(r"programmed X (-?[0-9.]+)  Y (-?[0-9.]+)  Z (-?[0-9.]+)", text)
    machine_tip = re.search(r"machine frame tip (-?[0-9.]+), (-?[0-9.]+), (-?[0-9.]+) mm", text)
    if not programmed or not machine_tip:
        return failures + [f"{fragment}: the readout has no programmed X Y Z or no machine frame tip: {text!r}"]
    if all(r["table"] for r in data["machine"]["rotary"]):
        xyz = [float(v) for v in programmed.groups()]
        tip = [float(v) for v in machine_tip.groups()]
        worst = max(abs(p - q) for p, q in zip(xyz, tip))
        print(f"{fragment}: machine tip {tip} vs programmed X Y Z {xyz}: {worst:.4f} mm apart")
        if worst > 0.01:
            failures.append(f"{fragment}: the machine frame tip {tip} is not the programmed X Y Z {xyz}")
    return failures


def check_verify_collision(browser, a, work, program):
    """A copy of `program` with the 20th feed block after the first G1 moved 1 mm along X (one side
    cuts into the blade): exit 4, a marker per hit labelled with its line, #marker=0 jumps there."""
    lines = open(program, encoding="utf-8").read().split("\n")
    g1 = next((i for i, l in enumerate(lines) if re.search(r"(^|\s)G0?1\s", l)), None)
    if g1 is None or g1 + 20 >= len(lines) or not re.search(r"X-?[0-9]", lines[g1 + 20]):
        return [f"{program}: no feed block with X 20 lines after the first G1 to move"]
    index = g1 + 20
    base, ext = os.path.splitext(os.path.basename(program))
    for delta in (-1.0, 1.0):
        edited = list(lines)
        edited[index] = re.sub(r"X(-?[0-9]+\.?[0-9]*)", lambda m: f"X{float(m.group(1)) + delta:.4f}", edited[index], count=1)
        bad = os.path.join(os.path.dirname(program), f"moved-{base}{ext}")  # beside the program's tool CSV
        open(bad, "w", encoding="utf-8").write("\n".join(edited))
        out = os.path.join(work, f"verify-moved{delta:+.0f}")
        p = subprocess.run([a.flankcam, "verify", "--job", a.job, bad, "--out", out], capture_output=True, text=True)
        os.remove(bad)
        if p.returncode == 0:
            continue
        if p.returncode != 4:
            return [f"verify of the moved program exited {p.returncode}: {p.stderr.strip()}"]
        page = os.path.join(out, "verify.html")
        data = view_data(page)
        hits = json.load(open(os.path.join(out, "verify.json"), encoding="utf-8"))["programs"][0]["collisions_and_gouges"]
        markers = [m for q in data["patches"] for m in q["markers"]]
        print(f"moved line {index + 1} by X{delta:+.0f}: {len(hits)} hit(s) on lines {sorted({h['line'] for h in hits})}, "
              f"{len(markers)} marker(s): {markers[0]['label'] if markers else None!r}")
        failures = []
        if len(markers) != len(hits) or not markers:
            return [f"the moved program's view has {len(markers)} markers for {len(hits)} hits"]
        marked = [int(re.search(r" line (\d+):", m["label"]).group(1)) for m in markers if re.search(r" line (\d+):", m["label"])]
        if sorted(marked) != sorted(h["line"] for h in hits) or index + 1 not in marked:
            failures.append(f"markers name lines {marked}, verify.json's hits {[h['line'] for h in hits]}, moved line {index + 1}")
        frame = markers[0]["frames"][0]
        fragment = "#view=only&marker=0"
        png = os.path.join(work, "verify-marker.png")
        # check_state checks the page is ready and its console clean, and returns the DOM it read.
        label, canvas, dom = check_state(browser, page, fragment, png, failures)
        readout = re.search(r'<div id="fcv-readout">([^<]*)</div>', dom)
        print(f"{fragment}: {label}, readout {readout.group(1) if readout else None!r}")
        if not label or not label.startswith(f"pose {frame + 1} / "):
            failures.append(f"verify.html {fragment} shows {label!r}, not pose {frame + 1}")
        if not readout or f"line {marked[0]} " not in readout.group(1):
            failures.append(f"verify.html {fragment}: the readout does not name line {marked[0]}")
        pink = marker_pixels(canvas)
        print(f"{fragment}: {pink} marker pixels")
        if pink < 5:
            failures.append(f"verify.html {fragment}: no collision marker on the canvas ({pink} pixels)")
        if a.save_verify:
            shutil.copyfile(png, a.save_verify)
            print(f"screenshot saved to {a.save_verify}")
        return failures
    return [f"moving line {index + 1} of {program} by 1 mm either way along X gouges nothing"]


def check_markers(browser, a, work):
    """Gouges at 1 um: markers, and #marker=M shows the marker's pose."""
    job = open(a.job, encoding="utf-8").read()
    base = os.path.dirname(os.path.abspath(a.job))
    job = re.sub(r"^surface: *(\S+)", lambda m: "surface: " + os.path.join(base, m.group(1)), job, flags=re.M)
    job = re.sub(r"^tolerance: *[0-9.]+", "tolerance: 0.001", job, flags=re.M)
    path = os.path.join(work, "gouge.yaml")
    open(path, "w", encoding="utf-8").write(job)
    out = os.path.join(work, "gouge")
    p = subprocess.run([a.flankcam, "run", path, "--out", out, "--quiet"], capture_output=True, text=True)
    if p.returncode != 4:
        return [f"the 1 um job should gouge (exit 4), exited {p.returncode}: {p.stderr.strip()}"]
    page = os.path.join(out, "report.html")
    html = open(page, encoding="utf-8").read()
    markers = re.findall(r'"pose":(\d+),"label":"[^"]*","frames":\[(-?\d+)', html)
    if len(markers) < 2:
        return [f"the 1 um job's view has {len(markers)} marker(s)"]
    pose = int(markers[1][0])
    dom, console = browser.dom("file://" + page + "#marker=1")
    state = re.search(r'<body[^>]*data-flankcam-viewer="([^"]*)"', dom)
    label = re.search(r'<span id="fcv-frame">([^<]*)</span>', dom)
    print(f"#marker=1 (worst pose {pose}): data-flankcam-viewer={state.group(1) if state else None!r}, "
          f"{label.group(1) if label else 'no pose label'}")
    failures = [f"#marker=1: console: {line}" for line in console]
    if not state or state.group(1) != "ready":
        failures.append(f"#marker=1: data-flankcam-viewer is {state.group(1) if state else 'missing'!r}")
    if not label or not label.group(1).startswith(f"pose {pose + 1} / "):
        failures.append(f"#marker=1 shows {label.group(1) if label else None!r}, not pose {pose + 1}")
    return failures


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--flankcam", required=True)
    ap.add_argument("--job", required=True)
    ap.add_argument("--work", required=True, help="scratch directory (emptied)")
    ap.add_argument("--save", help="copy the moved-slider screenshot here")
    ap.add_argument("--save-verify", help="copy the screenshot of verify.html's marker jump here")
    a = ap.parse_args()

    exe = find_browser()
    if not exe:
        if os.environ.get("FLANKCAM_REQUIRE_BROWSER") == "1":
            print("FAIL: no chromium (apt-get install chromium; .ci/install-deps does) and FLANKCAM_REQUIRE_BROWSER=1")
            return 1
        print("SKIP: no chromium on PATH (set FLANKCAM_REQUIRE_BROWSER=1 to make this a failure)")
        return 77
    shutil.rmtree(a.work, ignore_errors=True)
    os.makedirs(a.work)
    work = os.path.abspath(a.work)
    out = os.path.join(work, "run")
    p = subprocess.run([a.flankcam, "run", a.job, "--out", out, "--quiet"], capture_output=True, text=True)
    if p.returncode != 0:
        print(p.stdout, p.stderr)
        print(f"FAIL: flankcam run exited {p.returncode}")
        return 1
    page = os.path.join(out, "report.html")
    html = open(page, encoding="utf-8").read()
    if re.search(r'<script[^>]+src=|<link[^>]+href="?https?:|https?://[^"\s]*\.js', html):
        print("FAIL: report.html loads something from outside the page")
        return 1
    tracks = re.search(r'"tracks":\[(.*)\]\}\s*</script>', html, re.S)
    frames = [int(n) for n in re.findall(r'"frames":(\d+),"original_frames"', tracks.group(1))] if tracks else []
    if not frames:
        print("FAIL: the view has no posed program")
        return 1
    # The last track (the whole program when there are several patches), slider half way.
    track, pose = len(frames) - 1, frames[-1] // 2
    browser = Browser(exe, work)
    failures = []
    first_label, first, _ = check_state(browser, page, "#view=only", os.path.join(work, "first.png"), failures)
    moved_png = os.path.join(work, "moved.png")
    moved_label, moved, _ = check_state(browser, page, f"#view=only&track={track}&pose={pose}", moved_png, failures)
    expected = f"pose {pose + 1} / {frames[track]}"
    if moved_label != expected:
        failures.append(f"after moving the slider the view says {moved_label!r}, not {expected!r}")
    changed = sum(1 for r0, r1 in zip(first, moved) for p0, p1 in zip(r0, r1) if p0 != p1)
    print(f"pixels changed by moving the slider: {changed}")
    if changed < 1000:
        failures.append(f"moving the slider changed only {changed} pixels of the canvas")
    failures += check_markers(browser, a, work)
    failures += check_verify(browser, a, work, out)
    if a.save:
        shutil.copyfile(moved_png, a.save)
        print(f"screenshot saved to {a.save}")
    for f in failures:
        print("FAIL:", f)
    if not failures:
        print("OK: the 3D view of report.html and verify.html is ready, error-free, shows the deviation bands, follows "
              "the slider and jumps to markers")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
