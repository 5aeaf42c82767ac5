#!/usr/bin/env bash
# Runs the cohort workflow into WORK_DIR with the given caps program and checks it:
#   * the cohort is patients.tsv (two face phantoms of different size and Cranium) plus a
#     deliberately broken patient (a volume file that is not a volume), with the two plans of
#     plans.tsv placed relative to the glabella, on 2 cores;
#   * results.tsv has one row per patient x plan; the broken patient's rows are "failed" with
#     the error and every other row is "ok" (it failed alone), and report.html lists it;
#   * one ok row per plan has the closing force and lengthening of `caps simulate` run by hand on
#     the workflow's model and plan, and every Z-plasty's lengthening is within its known bounds;
#   * a rerun has nothing to do.
#   workflows/cohort/run_check.sh build/tools/caps /tmp/cohort [CONFIG]
# CONFIG defaults to config.yaml.
set -euo pipefail
caps="$1"
work="$2"
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
config="${3:-$here/config.yaml}"
python=/usr/bin/python3
rm -rf "$work"
mkdir -p "$work"
# The cohort's patients and the broken one.
table_path() {  # the config's table KEY as a path
  "$python" -c "import sys,yaml,os; p=yaml.safe_load(open(sys.argv[1])).get(sys.argv[3]); print('' if not p else p if os.path.isabs(p) else os.path.join(sys.argv[2], p))" "$config" "$here" "$1"
}
patients_src=$(table_path patients)
export CAPS_PLANS=$(table_path plans)
export CAPS_LESIONS=$(table_path lesions)  # empty: no lesions, no suggestions
cp "$patients_src" "$work/patients.tsv"
echo "this is not a volume" > "$work/broken.nii.gz"
printf 'broken\tvolume\t%s\t\n' "$work/broken.nii.gz" >> "$work/patients.tsv"
args=(-s "$here/Snakefile" --configfile "$config" --config "caps=$caps" "patients=$work/patients.tsv"
      --directory "$work" --cores 2)
start=$(date +%s.%N)
snakemake "${args[@]}" -q > "$work/snakemake.log" 2>&1 || { cat "$work/snakemake.log"; exit 1; }
end=$(date +%s.%N)
# The rerun's dry run goes on beside the checks (it reads the workflow's files, the checks write
# only under direct/, which no rule makes).
snakemake "${args[@]}" -n > "$work/rerun.log" 2>&1 &
rerun=$!
"$python" - "$work" "$caps" "$here" <<'EOF'
import concurrent.futures, csv, json, math, os, subprocess, sys
work, caps = sys.argv[1], sys.argv[2]
sys.path.insert(0, sys.argv[3])
from plans import expand_plans, lesion_shape, plan_options, simulate_arguments, simulate_options
patients = [r["patient"] for r in csv.DictReader(open(f"{work}/patients.tsv"), delimiter="\t")]
rows = list(csv.DictReader(open(f"{work}/results.tsv"), delimiter="\t"))
plans = sorted({r["plan"] for r in rows})
assert len(rows) == len(patients) * len(plans) == len({(r["patient"], r["plan"]) for r in rows}), \
    f"{len(rows)} rows for {len(patients)} patients x {len(plans)} plans"
for r in rows:
    if r["patient"] == "broken":
        assert r["status"] == "failed" and r["error"], r
    else:
        assert r["status"] == "ok", r
        assert float(r["closing_force_n"]) > 0 and float(r["thickness_mm"]) > 0, r
report = open(f"{work}/report.html").read()
assert "broken" in report and "failed" in report
# Every ok row equals caps simulate run by hand on the workflow's own model and plan (the models
# are not rebuilt) with the plan's mesh size and simulate options: the closing force of its
# result.json and the lengthening of its --json (two at a time, as the workflow runs).
plan_rows = {p["plan"]: p for p in csv.DictReader(
    (l for l in open(os.environ["CAPS_PLANS"]) if not l.startswith("#")), delimiter="\t")}
plan_rows = expand_plans(plan_rows, simulate_options(caps)
                         if any(p.get("simulate") for p in plan_rows.values()) else None)
def simulate(r):
    out = f"{work}/direct/{r['patient']}/{r['plan']}"
    os.makedirs(os.path.dirname(out), exist_ok=True)
    run = subprocess.run([caps, "simulate", "--model", f"{work}/models/{r['patient']}",
                          "--plan", f"{work}/plans/{r['patient']}/{r['plan']}.json", "-o", out,
                          "--mesh-size", plan_rows[r["plan"]]["mesh_size"] or "2.0",
                          *simulate_arguments(plan_rows[r["plan"]]).split(), "-q", "--json"],
                         check=True, capture_output=True, text=True)
    return r, json.load(open(f"{out}/result.json")), json.loads(run.stdout)
ok = [r for r in rows if r["status"] == "ok"]
# One row per plan is run again by hand (the first patient's: every row is made by the same rule,
# and each whole-face closure takes 10-40 s on the CI machine).
by_hand = [next(r for r in ok if r["plan"] == plan) for plan in plans if any(r["plan"] == plan for r in ok)]
with concurrent.futures.ThreadPoolExecutor(2) as pool:
    for r, result, summary in pool.map(simulate, by_hand):
        where = (r["patient"], r["plan"])
        direct = result["total_suture_force_n"]
        assert abs(direct - float(r["closing_force_n"])) <= 1e-9 * max(1.0, abs(direct)), \
            (where, direct, r["closing_force_n"])
        gain = summary["lengthening"]["mm"]
        assert abs(gain - float(r["lengthening_mm"])) <= 1e-9 * max(1.0, abs(gain)), \
            (where, gain, r["lengthening_mm"])
        assert abs(summary["lengthening"]["percent"] - float(r["lengthening_percent"])) <= 1e-3, where
# The Z-plasty lengthens its central limb by more than a tenth and by less than the rigid flaps'
# geometric sqrt(5 - 4 cos angle) - 1 (73 % at 60 deg, 47 % at 45; tests/test_app.cpp); its
# length along the axis before closure is the limb's.
zs = [r for r in ok if r["template"] == "z-plasty"]
for r in zs:
    gain, percent = float(r["lengthening_mm"]), float(r["lengthening_percent"])
    values = dict(p.split("=") for p in r["parameters"].split(";"))
    limb, angle = float(values["length"]), math.radians(float(values.get("angle", 60)))
    assert 0.1 * limb < gain and percent < 100 * (math.sqrt(5 - 4 * math.cos(angle)) - 1), r
    assert abs(100 * gain / percent - limb) < 0.5, (r["patient"], 100 * gain / percent, limb)
assert all(r["lengthening_mm"] == "" for r in rows if r["status"] != "ok")
# Suggestions (config "lesions"): one row per patient x lesion, the broken patient failed alone;
# the first patient's again by hand with caps plan suggest gives the same best design and force;
# on Cranium's forehead the relaxed skin tension lines are horizontal.
suggested = ""
if os.environ.get("CAPS_LESIONS"):
    lesions = {l["lesion"]: l for l in csv.DictReader(
        (x for x in open(os.environ["CAPS_LESIONS"]) if not x.startswith("#")), delimiter="\t")}
    srows = list(csv.DictReader(open(f"{work}/suggestions.tsv"), delimiter="\t"))
    assert len(srows) == len(patients) * len(lesions), (len(srows), len(patients), len(lesions))
    for r in srows:
        if r["patient"] == "broken":
            assert r["status"] == "failed" and r["error"], r
        else:
            assert r["status"] == "ok" and float(r["best_max_suture_force_n"]) > 0, r
    first = next(r for r in srows if r["status"] == "ok")
    l = lesions[first["lesion"]]
    out = f"{work}/direct_suggestion"
    subprocess.run([caps, "plan", "suggest", "--model", f"{work}/models/{first['patient']}",
                    "--at", l["at"], *lesion_shape(l), "--margin", l["margin"],
                    *plan_options({"parameters": l["suggest"]}).split(), "-o", out, "-q"],
                   check=True, capture_output=True, text=True)
    direct = json.load(open(f"{out}/suggestions.json"))
    best = next(d for d in direct["designs"] if d["name"] == direct["best"])
    assert first["best"] == direct["best"], (first, direct["best"])
    assert abs(float(first["best_max_suture_force_n"]) -
               best["sweep"]["max_force_per_suture_n"]) <= 1e-9, (first, best)
    cranium = [r for r in srows if r["patient"] == "cranium" and r["status"] == "ok"]
    for r in cranium:
        assert r["skin_lines_zone"] == "forehead" and abs(float(r["skin_lines_deg"]) - 90) < 5, r
    suggested = (f"; {len(srows)} suggestions, {first['patient']}'s equal caps plan suggest's "
                 f"(best {first['best']}), Cranium's skin lines horizontal")
print(f"cohort: {len(rows)} rows ({len(ok)} ok, broken failed alone); {len(by_hand)} rows' closing "
      f"force and lengthening equal caps simulate's; {len(zs)} Z-plasties lengthen "
      + ", ".join(f"{float(r['lengthening_percent']):.1f} %" for r in zs) + suggested)
EOF
wait "$rerun" || true
grep -q "Nothing to be done" "$work/rerun.log" || { cat "$work/rerun.log"; echo "a rerun would do work"; exit 1; }
echo "cohort: wall time $(python3 -c "print(round($end - $start, 1))") s on 2 cores; a rerun has nothing to do"
