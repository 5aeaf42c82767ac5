"""The cohort's summary report: report.html with the results table, the failed patients and two
plots (the closing force by procedure; the closing force against the soft-tissue thickness at
the site), from results.tsv.

    report.py results.tsv report.html force_by_procedure.png force_vs_thickness.png
"""

import csv
import html
import os
import sys

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


def number(x):
    try:
        return float(x)
    except (TypeError, ValueError):
        return None


def finish(fig, ax, title, path):
    """Labels the force axis, titles the plot and writes it to `path` (renamed into place)."""
    ax.set_ylabel("closing force (N)")
    ax.set_title(title)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path + ".tmp.png", dpi=100)
    os.replace(path + ".tmp.png", path)
    plt.close(fig)


def main(table, report, by_procedure, by_thickness):
    with open(table, newline="") as f:
        rows = list(csv.DictReader(f, delimiter="\t"))
    ok = [r for r in rows if r["status"] == "ok"]
    failed = [r for r in rows if r["status"] != "ok"]
    os.makedirs(os.path.dirname(by_procedure) or ".", exist_ok=True)

    # Closing force by procedure: one column of points per plan, one colour per patient.
    plans = sorted({r["plan"] for r in rows})
    patients = sorted({r["patient"] for r in rows})
    fig, ax = plt.subplots(figsize=(6, 4))
    for k, patient in enumerate(patients):
        xs, ys = [], []
        for r in ok:
            if r["patient"] == patient and number(r["closing_force_n"]) is not None:
                xs.append(plans.index(r["plan"]) + 0.08 * (k - (len(patients) - 1) / 2))
                ys.append(number(r["closing_force_n"]))
        ax.scatter(xs, ys, label=patient)
    ax.set_xticks(range(len(plans)))
    ax.set_xticklabels(plans)
    finish(fig, ax, "Closing force by procedure", by_procedure)

    # Closing force against the soft-tissue thickness at the plan's centre.
    fig, ax = plt.subplots(figsize=(6, 4))
    for plan in plans:
        pts = [(number(r["thickness_mm"]), number(r["closing_force_n"])) for r in ok
               if r["plan"] == plan]
        pts = [p for p in pts if None not in p]
        ax.scatter([p[0] for p in pts], [p[1] for p in pts], label=plan)
    ax.set_xlabel("soft-tissue thickness at the site, along the normal (mm)")
    finish(fig, ax, "Closing force against local thickness", by_thickness)

    columns = list(rows[0].keys()) if rows else []
    head = "".join(f"<th>{html.escape(c)}</th>" for c in columns)
    body = "".join(
        "<tr>" + "".join(f"<td>{html.escape(r[c] or '')}</td>" for c in columns) + "</tr>"
        for r in rows)
    failures = "".join(f"<li>{html.escape(r['patient'])} / {html.escape(r['plan'])}: "
                       f"{html.escape(r['error'])}</li>" for r in failed)
    rel = lambda p: os.path.relpath(p, os.path.dirname(report) or ".")  # noqa: E731
    text = f"""<!doctype html><html><head><meta charset="utf-8"><title>caps cohort</title>
<style>body{{font-family:sans-serif}} td,th{{padding:2px 6px;border-bottom:1px solid #ddd}}</style>
</head><body><h1>caps cohort</h1>
<p>{len(patients)} patients x {len(plans)} plans: {len(ok)} simulated, {len(failed)} failed.</p>
{"<h2>Failed</h2><ul>" + failures + "</ul>" if failed else ""}
<img src="{rel(by_procedure)}"> <img src="{rel(by_thickness)}">
<h2>Results</h2><table><tr>{head}</tr>{body}</table></body></html>
"""
    with open(report + ".tmp", "w") as f:
        f.write(text)
    os.replace(report + ".tmp", report)


if __name__ == "__main__":
    main(*sys.argv[1:5])
