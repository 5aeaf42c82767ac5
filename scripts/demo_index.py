#!/usr/bin/env python3
"""Writes the demo's index.html (scripts/demo.sh): the patient model, and for each plan its
pictures, its closure's forces and feature distortions (from result.json and summary.json, which
caps simulate writes) and its operating-room sheet (caps plan sheet); the 3D Slicer folder where
the demo made one.

    python3 scripts/demo_index.py OUT PLAN [PLAN ...]
"""
import html
import json
import os
import sys


def load(path):
    try:
        with open(path, encoding="utf-8") as f:
            return json.load(f)
    except (OSError, ValueError):
        return None


def number(x, digits):
    return "&ndash;" if x is None else f"{x:.{digits}f}"


def closure(out, plan):
    """The closing force, the largest suture's force, the features and the warnings of a plan's
    result folder (None where it has no result.json)."""
    result = load(os.path.join(out, plan, "result.json"))
    if result is None:
        return None
    summary = load(os.path.join(out, plan, "summary.json")) or {}
    spacing = result.get("sutures_at_spacing", {})
    warnings = list(result.get("warnings", []))
    warnings += [w for w in summary.get("warnings", []) if w not in warnings]
    return {
        "closing_force_n": result.get("total_suture_force_n"),
        "max_suture_force_n": spacing.get("max_suture_force_n"),
        "sutures": spacing.get("n_sutures"),
        "spacing_mm": spacing.get("spacing_mm"),
        "features": [f for f in summary.get("features", []) if f.get("has_value")],
        "features_recorded": "features" in summary,
        "warnings": warnings,
    }


def features_html(c):
    if not c["features_recorded"]:
        return "not recorded (run caps simulate again)"
    if not c["features"]:
        return "none reached"
    items = []
    still = [f for f in c["features"] if (f.get("max_mm") or 0) < 0.05]
    moved = [f for f in c["features"] if (f.get("max_mm") or 0) >= 0.05]
    for f in sorted(moved, key=lambda f: -(f.get("max_mm") or 0)):
        text = html.escape(f.get("sentence", f.get("name", "")))
        if f.get("warning"):
            text += f' <strong class="warn">{html.escape(f["warning"])}</strong>'
        items.append(f"<li>{text}</li>")
    if still:
        names = ", ".join(html.escape(f.get("name", "").replace("_", " ")) for f in still)
        items.append(f"<li>moved less than 0.05 mm: {names}</li>")
    return "<ul>" + "".join(items) + "</ul>"


def main():
    out, plans = sys.argv[1], sys.argv[2:]
    page = []
    w = page.append
    w("""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>caps demo: Cranium.inv3</title>
<style>body{font-family:DejaVu Sans,Arial,sans-serif;max-width:1150px;margin:2em auto;color:#222}
img{max-width:100%;border:1px solid #ddd}.row{display:flex;gap:12px}.row div{flex:1}
table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:4px 8px;vertical-align:top;text-align:left}
td.n{text-align:right;white-space:nowrap}ul{margin:0;padding-left:1.2em}.warn{color:#b34700}</style></head>
<body>
<h1>caps demo: a patient model from CT, three plans, their closure</h1>
<p>The patient: <code>Cranium.inv3</code>, a head CT from Debian's invesalius-examples. caps measured
the soft-tissue thickness between skin and bone in the CT and built a volumetric model of the
soft tissue of the whole face (tetrahedra between skin and bone, <code>cranium/tissue.vtu</code>),
planned an elliptical excision, a Z-plasty and a V-Y advancement flap on the forehead, meshed each
plan (20-node hexahedra and 15-node wedges down to the measured bone), tied that patch into the
whole-face model (no clamped rim), closed the wound with suture constraints and rendered the skin
before and after at the CT's full resolution; <code>summary.json</code> says how far the closure
moves the brows, eyelid margins and alar rims. Each plan is also simulated with a constant
thickness (the 1992 CAPS assumption for surface scans) for comparison, on the 1992 clamped
patch, and has an operating-room sheet: the incision 1:1 on the skin laid flat, its points
measured from landmarks a surgeon can palpate, the predicted forces (PDF to print at 100 %).</p>
""")
    # The plans side by side.
    w("<h2>The plans' closures</h2>\n<table><tr><th>plan</th><th>closing force (N)</th>"
      "<th>largest suture (N)</th><th>feature distortions</th><th>operating-room sheet</th></tr>\n")
    for p in plans:
        c = closure(out, p)
        sheet = f"{p}-sheet.pdf"
        link = (f'<a href="{html.escape(sheet)}">PDF</a>' if os.path.exists(os.path.join(out, sheet))
                else "&ndash;")
        if c is None:
            w(f"<tr><td>{html.escape(p)}</td><td colspan=3>not simulated</td><td>{link}</td></tr>\n")
            continue
        per = (f" ({c['sutures']} sutures every {c['spacing_mm']:g} mm)"
               if c["sutures"] and c["spacing_mm"] else "")
        w(f'<tr><td><a href="#{html.escape(p)}">{html.escape(p)}</a></td>'
          f'<td class="n">{number(c["closing_force_n"], 2)}</td>'
          f'<td class="n">{number(c["max_suture_force_n"], 2)}{per}</td>'
          f"<td>{features_html(c)}</td><td>{link}</td></tr>\n")
    w("</table>\n<p>Closing force: the suture pairs' forces added; largest suture: the force on "
      "the most loaded suture when the wound is closed with sutures at that spacing.</p>\n")
    w("""<h2>The patient model</h2>
<div class="row"><div><p>Soft-tissue thickness (mm)</p><img src="cranium/thickness.png" alt="thickness map"></div>
<div><p>Skin range image</p><img src="cranium/skin.png" alt="skin range image"></div></div>
<p>Files: <code>cranium/model.json</code>, the NRRD maps (3D Slicer), <code>skin.ply</code>,
<code>bone.ply</code> (3D Slicer, ParaView, Blender), <code>tissue.vtu</code> (ParaView),
<code>skin.vdb</code> and <code>bone.vdb</code> (the level sets; Blender, Houdini).</p>
""")
    for slicer in ("slicer", "cranium/slicer"):
        if os.path.isdir(os.path.join(out, slicer)):
            w(f'<p>3D Slicer: <a href="{slicer}/">{slicer}/</a> (the CT, the segmentation, the '
              "surfaces and the markups, in the patient's space; docs/slicer.md).</p>\n")
            break
    for p in plans:
        e = html.escape(p)
        w(f"""<h2 id="{e}">{e}</h2>
<div class="row"><div><p>The plan</p><img src="{e}.png" alt="{e} plan"></div>
<div><p>The surface mesh</p><img src="{e}/surface.png" alt="{e} surface mesh"></div></div>
<div class="row"><div><p>Before</p><img src="{e}/pre_plan.png" alt="{e} before"></div>
<div><p>After the closure</p><img src="{e}/post_plan.png" alt="{e} after"></div></div>
<div class="row"><div><p>Before, oblique</p><img src="{e}/pre_oblique.png" alt="{e} before, oblique"></div>
<div><p>After, oblique</p><img src="{e}/post_oblique.png" alt="{e} after, oblique"></div></div>
<div class="row"><div><p>Skin tension after the closure (kPa)</p><img src="{e}/tension_plan.png" alt="{e} skin tension"></div>
""")
        preview = f"{p}-sheet-preview.png"
        if os.path.exists(os.path.join(out, preview)):
            w(f'<div><p>The operating-room sheet (<a href="{e}-sheet.pdf">PDF</a>, '
              f'<a href="{e}-sheet.png">PNG</a>; this preview is the PDF as poppler draws it)</p>'
              f'<a href="{e}-sheet.pdf"><img src="{html.escape(preview)}" alt="{e} sheet"></a></div></div>\n')
        else:
            w("<div></div></div>\n")
        c = closure(out, p)
        if c is not None:
            w(f"<p>Closing force {number(c['closing_force_n'], 2)} N, largest suture "
              f"{number(c['max_suture_force_n'], 2)} N. Feature distortions: {features_html(c)}</p>\n")
            if c["warnings"]:
                w('<p class="warn">Warnings:</p><ul class="warn">' +
                  "".join(f"<li>{html.escape(x)}</li>" for x in c["warnings"]) + "</ul>\n")
        for slicer in (f"{p}-slicer", f"{p}/slicer"):
            if os.path.isdir(os.path.join(out, slicer)):
                w(f'<p>3D Slicer: <a href="{html.escape(slicer)}/">{html.escape(slicer)}/</a></p>\n')
                break
        w(f"""<p><a href="{e}-compare/report.html">Measured versus constant thickness</a> (in the whole face: the
thickness under the wound's patch differs, the face around it is the same) &middot;
<code>{e}/result.vtu</code> (ParaView) &middot; <code>{e}/mesh.inp</code> (CalculiX) &middot;
<code>{e}/result.json</code> (closing force, stresses, timings) &middot;
<code>{e}/summary.json</code> (the closure in short: forces per suture, feature lines)</p>
""")
    w("</body></html>\n")
    tmp = os.path.join(out, ".index.html.tmp")
    with open(tmp, "w", encoding="utf-8") as f:
        f.write("".join(page))
    os.replace(tmp, os.path.join(out, "index.html"))


if __name__ == "__main__":
    main()
