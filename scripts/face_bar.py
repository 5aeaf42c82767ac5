#!/usr/bin/env python3
"""Where on the face a small ellipse can be planned and simulated (issue 16's bar).

Runs the caps program (plan new, then simulate) on a patient model at the 18 cheek and
nasal-dorsum points (theta -60/-45/45/60 deg at z 25/35/45 mm, theta -5/0/5 at z 45/55) and over
a 10 deg x 10 mm grid (theta -60..60, z over the model's rows). Where the model cannot represent
the skin, caps plan new itself places the plan on a local chart beside it; with --no-auto-chart
it is asked not to (--no-chart), and with --charts a refused plan is tried again on a chart made
by hand (caps model chart, as the refusal advises). Prints the counts and the
reasons for failure as a markdown table; --json writes every outcome, --svg draws them. Every count comes from the
caps program's exit code and message: nothing is computed here.

  scripts/face_bar.py build/tools/caps out/cranium /tmp/bar --json /tmp/bar/cranium.json
"""
import argparse
import json
import os
import subprocess
import sys

# Cranium's face landmark (model.json statistics.face, the nose), where the points were chosen.
CRANIUM_FACE = (-1.40625, 41.15)
POINTS = [(t, z) for t in (-60, -45, 45, 60) for z in (25, 35, 45)] + \
         [(t, z) for t in (-5, 0, 5) for z in (45, 55)]


# extra arguments of caps plan new (--no-auto-chart: ["--no-chart"])
PLAN_NEW_ARGS = []


def run(cmd):
    p = subprocess.run(cmd, capture_output=True, text=True)
    msg = (p.stderr.strip().splitlines() or [""])[-1]
    return p.returncode, msg


def reason(msg):
    """A short class of a refusal, from the caps message."""
    for key in ("not operable", "cannot represent", "no base under", "eye)", "no_bone", "undercut",
                "grazing", "truncated", "no_skin", "outside the model", "top or bottom",
                "overlaps itself", "inverted",
                "under-constrained", "thickness"):
        if key in msg:
            return key
    return msg[:60]


def attempt_on(caps, model, work, tag, at, length, width):
    plan = os.path.join(work, tag + ".json")
    rc, msg = run([caps, "plan", "new", "ellipse", "--model", model, "--at", at,
                   "--length", str(length), "--width", str(width), "-o", plan, "--force",
                   "--quiet"] + PLAN_NEW_ARGS)
    if rc != 0:
        return {"planned": False, "simulated": False, "message": msg}
    # caps plan new places a plan where the model cannot hold the skin on a local chart it makes
    # beside the plan (PLAN.chart), which the plan names as its model
    with open(plan) as f:
        on_chart = json.load(f).get("model", "").endswith(".chart")
    rc, msg = run([caps, "simulate", "--model", model, "--plan", plan, "-o",
                   os.path.join(work, tag), "--force", "--quiet"])
    return {"planned": True, "simulated": rc == 0, "message": "" if rc == 0 else msg,
            "chart": on_chart, "chart_made_by_plan_new": on_chart}


def attempt(caps, model, work, theta, z, length, width, charts):
    """The ellipse at (theta, z) of the model; with `charts`, where the model cannot represent
    the skin there (grazing, undercut), again on a local chart facing it (caps model chart), as
    the refusal's advice says."""
    tag = f"t{theta}_z{z}".replace("-", "m")
    r = {"theta": theta, "z": z, "chart": False}
    r.update(attempt_on(caps, model, work, tag, f"{theta},{z}", length, width))
    if r["simulated"] or r["chart"] or not charts or "not operable" in r["message"] or not any(
            k in r["message"] for k in ("cannot represent", "grazing", "undercut")):
        return r
    chart = os.path.join(work, "chart_" + tag)
    rc, msg = run([caps, "model", "chart", model, "--at", f"{theta},{z}", "-o", chart,
                   "--force", "--quiet"])
    if rc != 0:
        r["chart_message"] = msg
        return r
    c = attempt_on(caps, chart, work, "chart_" + tag + "_plan", "0,0", length, width)
    if c["planned"] or c["simulated"]:
        r.update(c)
        r["chart"] = True
    else:
        r["chart_message"] = c["message"]
    return r


COLOURS = [("simulated", "#2e9d4a"), ("simulated on a chart", "#2f6fd0"),
           ("planned, not simulated", "#f0a030"), ("not operable: the eye", "#9a9a9a"),
           ("not operable: outside the scan", "#d8d8d8"), ("refused", "#d03a2f")]


def outcome(r):
    if r["simulated"]:
        return "simulated on a chart" if r.get("chart") else "simulated"
    if r["planned"]:
        return "planned, not simulated"
    if "lies on the eye" in r["message"]:
        return "not operable: the eye"
    return "not operable: outside the scan" if "not operable" in r["message"] else "refused"


def write_svg(path, out, title):
    """The outcomes over (theta, z): grid points as squares, the 18 points as circles."""
    rows = out["grid"] + out["points"]
    zs = [r["z"] for r in rows]
    ts = [r["theta"] for r in rows]
    z_lo, z_hi = min(zs) - 10, max(zs) + 10
    t_lo, t_hi = min(ts) - 10, max(ts) + 10
    sx, sz, left, top = 5.0, 5.0, 60, 40  # px per deg, px per mm, margins
    w = int(left + max(140, t_hi - t_lo) * sx + 20)
    h = int(top + (z_hi - z_lo) * sz + 130)
    X = lambda t: left + (t - t_lo) * sx
    Y = lambda z: top + (z_hi - z) * sz
    colour = dict(COLOURS)
    e = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{w}" height="{h}" '
         f'font-family="sans-serif" font-size="12">',
         f'<rect width="{w}" height="{h}" fill="white"/>',
         f'<text x="{left}" y="20" font-size="14">{title}</text>']
    for t in range(30 * int(t_lo // 30 + 1), int(t_hi) + 1, 30):
        e.append(f'<line x1="{X(t)}" y1="{Y(z_hi)}" x2="{X(t)}" y2="{Y(z_lo)}" stroke="#ddd"/>')
        e.append(f'<text x="{X(t)}" y="{Y(z_lo) + 16}" text-anchor="middle">{t}</text>')
    for z in range(10 * int(z_lo // 10 + 1), int(z_hi) + 1, 20):
        e.append(f'<line x1="{X(t_lo)}" y1="{Y(z)}" x2="{X(t_hi)}" y2="{Y(z)}" stroke="#ddd"/>')
        e.append(f'<text x="{left - 6}" y="{Y(z) + 4}" text-anchor="end">{z}</text>')
    e.append(f'<text x="{X(0.5 * (t_lo + t_hi))}" y="{Y(z_lo) + 32}" text-anchor="middle">theta (deg): 0 = the '
             f'face, + = the patient\'s left</text>')
    e.append(f'<text x="14" y="{Y((z_lo + z_hi) / 2)}" transform="rotate(-90 14 '
             f'{Y((z_lo + z_hi) / 2)})" text-anchor="middle">z (mm)</text>')
    for r in out["grid"]:
        e.append(f'<rect x="{X(r["theta"]) - 20}" y="{Y(r["z"]) - 20}" width="40" height="40" '
                 f'fill="{colour[outcome(r)]}" stroke="white" stroke-width="2"/>')
    for r in out["points"]:
        e.append(f'<circle cx="{X(r["theta"])}" cy="{Y(r["z"])}" r="9" '
                 f'fill="{colour[outcome(r)]}" stroke="black" stroke-width="1.5"/>')
    y = Y(z_lo) + 52
    for i, (name, c) in enumerate(COLOURS):
        x = left + (i % 3) * 230
        yy = y + (i // 3) * 18
        e.append(f'<rect x="{x}" y="{yy - 10}" width="12" height="12" fill="{c}"/>')
        e.append(f'<text x="{x + 16}" y="{yy}">{name}</text>')
    e.append(f'<text x="{left}" y="{y + 40}">squares: the 10 deg x 10 mm grid; circles: the 18 '
             f'cheek and nasal-dorsum points</text>')
    e.append("</svg>")
    with open(path, "w") as f:
        f.write("\n".join(e) + "\n")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("caps")
    ap.add_argument("model")
    ap.add_argument("work")
    ap.add_argument("--length", type=float, default=12.0, help="ellipse length (mm)")
    ap.add_argument("--width", type=float, default=4.0, help="ellipse width (mm)")
    ap.add_argument("--grid-z", default="", help="z range of the grid LO,HI (mm); default: "
                    "from 10 mm above the model's bottom (the mesher keeps its end rows free) "
                    "to 70 mm above the face landmark (the nose)")
    ap.add_argument("--no-grid", action="store_true")
    ap.add_argument("--from-face", action="store_true", help="place the 18 points and the grid "
                    "relative to this model's face landmark (statistics.face), as they lie "
                    "relative to Cranium's (theta -1.4 deg, z 41.2 mm): for other scans")
    ap.add_argument("--charts", action="store_true", help="where the model cannot represent the "
                    "skin (grazing, undercut), try again on a local chart (caps model chart)")
    ap.add_argument("--no-auto-chart", action="store_true", help="caps plan new --no-chart: "
                    "refuse where the model cannot represent the skin instead of planning on a "
                    "local chart (the head's model alone, as before 5 December 2026)")
    ap.add_argument("--json", default="")
    ap.add_argument("--svg", default="", help="write the outcomes as a picture (SVG)")
    a = ap.parse_args()
    if a.no_auto_chart:
        PLAN_NEW_ARGS.append("--no-chart")
    os.makedirs(a.work, exist_ok=True)
    info = json.load(open(os.path.join(a.model, "model.json")))
    g = info["grid"]
    face_z = info["statistics"]["face"]["z_mm"]
    z_top = g["z0_mm"] + (g["n_z"] - 1) * g["dz_mm"]
    if a.grid_z:
        lo, hi = (float(x) for x in a.grid_z.split(","))
    else:
        lo, hi = g["z0_mm"] + 10, min(z_top - 10, face_z + 70)
    dt = dz = 0.0
    if a.from_face:
        dt = round(info["statistics"]["face"]["theta_deg"] - CRANIUM_FACE[0], 1)
        dz = round(face_z - CRANIUM_FACE[1], 1)
    out = {"model": a.model, "ellipse_mm": [a.length, a.width], "points": [], "grid": [],
           "offset_from_cranium": [dt, dz]}
    for t, z in ((t + dt, z + dz) for t, z in POINTS):
        out["points"].append(attempt(a.caps, a.model, a.work, t, z, a.length, a.width, a.charts))
        print(f"point {t},{z}: {out['points'][-1]}", file=sys.stderr, flush=True)
    if not a.no_grid:
        z0 = 10 * int(-(-lo // 10))
        for z in range(z0, int(hi) + 1, 10):
            for t in (t + dt for t in range(-60, 61, 10)):
                out["grid"].append(attempt(a.caps, a.model, a.work, t, z, a.length, a.width, a.charts))
                print(f"grid {t},{z}: {out['grid'][-1]}", file=sys.stderr, flush=True)
    for key in ("points", "grid"):
        rows = out[key]
        if not rows:
            continue
        planned = sum(r["planned"] for r in rows)
        simulated = sum(r["simulated"] for r in rows)
        charted = sum(r["simulated"] and r.get("chart", False) for r in rows)
        why = {}
        for r in rows:
            if not r["simulated"]:
                k = reason(r["message"])
                why[k] = why.get(k, 0) + 1
        print(f"| {key} | {len(rows)} | {planned} | {simulated} ({charted} on a chart) | "
              f"{', '.join(f'{k} {v}' for k, v in sorted(why.items(), key=lambda x: -x[1]))} |")
    if a.json:
        with open(a.json, "w") as f:
            json.dump(out, f, indent=1)
    if a.svg:
        # named by the scan the model was made from, not by the model's directory
        scan = os.path.basename(os.path.normpath(info.get("source", {}).get("path", a.model)))
        write_svg(a.svg, out, f"Where a {a.length:g} x {a.width:g} mm ellipse can be planned and "
                  f"simulated: {scan}")


if __name__ == "__main__":
    main()
