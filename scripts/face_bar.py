#!/usr/bin/env python3
"""Where on the face a small ellipse can be planned and simulated (issue 16's bar).

Runs the caps program (plan new, then simulate) on a patient model at the 18 cheek and
nasal-dorsum points (theta -60/-45/45/60 deg at z 25/35/45 mm, theta -5/0/5 at z 45/55) and over
a 10 deg x 10 mm grid (theta -60..60, z over the model's rows), with --charts again on a local
chart where the model cannot represent the skin (as the refusal advises), and prints the counts and the
reasons for failure as a markdown table; --json writes every outcome. Every count comes from the
caps program's exit code and message: nothing is computed here.

  scripts/face_bar.py build/tools/caps out/cranium /tmp/bar --json /tmp/bar/cranium.json
"""
import argparse
import json
import os
import subprocess
import sys

POINTS = [(t, z) for t in (-60, -45, 45, 60) for z in (25, 35, 45)] + \
         [(t, z) for t in (-5, 0, 5) for z in (45, 55)]


def run(cmd):
    p = subprocess.run(cmd, capture_output=True, text=True)
    msg = (p.stderr.strip().splitlines() or [""])[-1]
    return p.returncode, msg


def reason(msg):
    """A short class of a refusal, from the caps message."""
    for key in ("not operable", "cannot represent", "no base under", "no_bone", "undercut",
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
                   "--quiet"])
    if rc != 0:
        return {"planned": False, "simulated": False, "message": msg}
    rc, msg = run([caps, "simulate", "--model", model, "--plan", plan, "-o",
                   os.path.join(work, tag), "--force", "--quiet"])
    return {"planned": True, "simulated": rc == 0, "message": "" if rc == 0 else msg}


def attempt(caps, model, work, theta, z, length, width, charts):
    """The ellipse at (theta, z) of the model; with `charts`, where the model cannot represent
    the skin there (grazing, undercut), again on a local chart facing it (caps model chart), as
    the refusal's advice says."""
    tag = f"t{theta}_z{z}".replace("-", "m")
    r = {"theta": theta, "z": z, "chart": False}
    r.update(attempt_on(caps, model, work, tag, f"{theta},{z}", length, width))
    if r["simulated"] or not charts or not any(
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
    ap.add_argument("--charts", action="store_true", help="where the model cannot represent the "
                    "skin (grazing, undercut), try again on a local chart (caps model chart)")
    ap.add_argument("--json", default="")
    a = ap.parse_args()
    os.makedirs(a.work, exist_ok=True)
    info = json.load(open(os.path.join(a.model, "model.json")))
    g = info["grid"]
    face_z = info["statistics"]["face"]["z_mm"]
    z_top = g["z0_mm"] + (g["n_z"] - 1) * g["dz_mm"]
    if a.grid_z:
        lo, hi = (float(x) for x in a.grid_z.split(","))
    else:
        lo, hi = g["z0_mm"] + 10, min(z_top - 10, face_z + 70)
    out = {"model": a.model, "ellipse_mm": [a.length, a.width], "points": [], "grid": []}
    for t, z in POINTS:
        out["points"].append(attempt(a.caps, a.model, a.work, t, z, a.length, a.width, a.charts))
        print(f"point {t},{z}: {out['points'][-1]}", file=sys.stderr, flush=True)
    if not a.no_grid:
        z0 = 10 * int(-(-lo // 10))
        for z in range(z0, int(hi) + 1, 10):
            for t in range(-60, 61, 10):
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


if __name__ == "__main__":
    main()
