"""The plans table's sweeps (workflows/cohort/plans.py): the values a sweep gives, the plan ids
and parameters it expands to, its refusals, and the workflow's dry run over plans_sweep.tsv
(one plan and one simulation per patient and value)."""

import collections
import csv
import json
import os
import re
import shutil
import subprocess
import sys

import pytest

HERE = os.path.dirname(os.path.abspath(__file__))
COHORT = os.path.dirname(HERE)
sys.path.insert(0, COHORT)

from plans import (check_simulate_values, expand_plans, lesion_shape,  # noqa: E402
                   parse_simulate_help, plan_options, simulate_arguments, simulate_options,
                   simulate_settings, sweep_values)

CRANIUM = "/usr/share/doc/invesalius-examples/examples/Cranium.inv3"
# The build's caps program (ctest passes it); the simulate options are checked against its own.
CAPS = os.environ.get("CAPS")


@pytest.fixture(scope="module")
def caps():
    if not CAPS or not os.access(CAPS, os.X_OK):
        pytest.skip("no caps program: set CAPS (ctest sets it to the build's)")
    return CAPS


@pytest.fixture(scope="module")
def options(caps):
    return simulate_options(caps)


def test_a_range_includes_its_stop_and_does_not_drift():
    assert sweep_values("30:90:15") == ["30", "45", "60", "75", "90"]
    assert sweep_values("30:80:15") == ["30", "45", "60", "75"]  # 90 is past the stop
    assert sweep_values("0.1:0.7:0.1") == ["0.1", "0.2", "0.3", "0.4", "0.5", "0.6", "0.7"]
    assert sweep_values("-10:10:10") == ["-10", "0", "10"]
    assert sweep_values("5:5:1") == ["5"]


def test_a_list_keeps_its_values_and_order():
    assert sweep_values("60, 30,45") == ["60", "30", "45"]
    assert sweep_values("12") == ["12"]


@pytest.mark.parametrize("text, says", [
    ("30:90", "start:stop:step"),
    ("30:90:0", "step > 0"),
    ("90:30:15", "start <= stop"),
    ("30:x:15", "'x' is not a number"),
    ("30:nan:15", "finite"),
    ("30,,45", "empty value"),
    ("30,45,30", "repeats"),
    ("30,a/b", "'a/b' is not a number"),
    ("0:100:0.5", "201 values"),
])
def test_a_malformed_sweep_is_refused_with_what_to_write(text, says):
    with pytest.raises(ValueError, match=re.escape(says)):
        sweep_values(text, "plan 'z', parameter 'angle'")


def test_a_row_expands_into_one_plan_per_value_with_readable_ids():
    rows = {
        "z": {"template": "z-plasty", "at": "glabella+0,25", "parameters": "length=15;angle=30:90:30"},
        "e": {"template": "ellipse", "at": "40,20", "parameters": "length=12,15;width=3,4"},
        "vy": {"template": "v-y-advancement", "at": "0,20", "parameters": "length=12;advance=3"},
    }
    plans = expand_plans(rows)
    assert list(plans) == ["z_angle30", "z_angle60", "z_angle90",
                           "e_length12_width3", "e_length12_width4",
                           "e_length15_width3", "e_length15_width4", "vy"]
    assert plans["z_angle60"]["parameters"] == "length=15;angle=60"
    assert plans["z_angle60"]["template"] == "z-plasty"
    assert plans["z_angle60"]["at"] == "glabella+0,25"
    assert plans["z_angle60"]["sweep_of"] == "z"
    assert plan_options(plans["e_length15_width3"]) == "--length 15 --width 3"
    assert plans["vy"]["parameters"] == "length=12;advance=3"
    assert plan_options({"parameters": "defect_angle=40"}) == "--defect-angle 40"


def test_an_id_used_twice_is_refused():
    with pytest.raises(ValueError, match="z_angle30.*used twice"):
        expand_plans({"z": {"parameters": "angle=30,45"}, "z_angle30": {"parameters": "angle=30"}})
    with pytest.raises(ValueError, match="not name=value"):
        expand_plans({"z": {"parameters": "angle30"}})


def test_the_simulate_options_are_read_from_caps_help():
    text = ("Usage: caps simulate [OPTIONS]\n\nOptions:\n"
            "  -h,--help                   Print this help message and exit\n"
            "  -o,--output TEXT REQUIRED   result directory to create\n"
            "  --undermine FLOAT=10        free the tissue from the bone within this distance\n"
            "                              --not-an-option, a description's next line\n"
            "  --constant-thickness FLOAT=0\n"
            "                              mesh a constant depth (mm)\n"
            "  --steps INT=10              neo-hookean: load steps\n"
            "  --render                    also render\n")
    assert parse_simulate_help(text) == {
        "help": (None, ""), "output": ("TEXT", ""), "undermine": ("FLOAT", "10"),
        "constant_thickness": ("FLOAT", "0"), "steps": ("INT", "10"), "render": (None, "")}


def test_the_build_caps_simulate_has_the_options_the_sweep_table_sets(options):
    for key, kind in [("undermine", "FLOAT"), ("prestretch", "FLOAT"), ("material", "TEXT"),
                      ("steps", "INT"), ("suture_spacing", "FLOAT"), ("render", None)]:
        assert options[key][0] == kind, (key, options[key])
    assert options["material"][1] == "neo-hookean" and options["prestretch"][1] == "1"


def test_simulate_options_orientation_and_mesh_size_sweep_with_readable_ids(options):
    rows = {
        "z": {"template": "z-plasty", "at": "glabella+0,25", "orientation": "90",
              "parameters": "length=15;angle=45,60", "mesh_size": "2.5",
              "simulate": "undermine=5,10;material=neo-hookean;prestretch=1.1"},
        "e": {"template": "ellipse", "at": "40,20", "orientation": "0:90:45",
              "parameters": "length=12", "mesh_size": "2,3",
              "simulate": "material=linear,neo-hookean"},
        "v": {"template": "v-y-advancement", "at": "0,20", "orientation": "", "parameters": "",
              "mesh_size": "", "simulate": "suture-spacing=4"},
    }
    plans = expand_plans(rows, options)
    assert list(plans) == [
        "z_angle45_undermine5", "z_angle45_undermine10", "z_angle60_undermine5",
        "z_angle60_undermine10",
        *(f"e_orientation{o}_mesh_size{m}_material{t}" for o in (0, 45, 90) for m in (2, 3)
          for t in ("linear", "neo-hookean")),
        "v"]
    z = plans["z_angle60_undermine10"]
    assert z["parameters"] == "length=15;angle=60" and z["orientation"] == "90"
    assert z["simulate"] == "undermine=10;material=neo-hookean;prestretch=1.1"
    assert z["sweep_of"] == "z" and z["swept"] == ["angle", "undermine"]
    assert simulate_arguments(z) == "--undermine 10 --material neo-hookean --prestretch 1.1"
    e = plans["e_orientation45_mesh_size3_materialneo-hookean"]
    assert (e["orientation"], e["mesh_size"], e["simulate"]) == ("45", "3", "material=neo-hookean")
    assert plan_options(e) == "--length 12"
    # A name with dashes is caps's option, spelled as its JSON key in the plan and the table.
    assert plans["v"]["simulate"] == "suture_spacing=4" and plans["v"]["swept"] == []
    assert simulate_arguments(plans["v"]) == "--suture-spacing 4"
    assert (plans["v"]["orientation"], plans["v"]["mesh_size"]) == ("", "")
    # The results table's columns: each option any plan sets, caps's default where one does not.
    assert simulate_settings(plans, options) == {
        "undermine": "10", "material": "neo-hookean", "prestretch": "1", "suture_spacing": "5"}
    check_simulate_values(CAPS, plans)  # caps takes every value


@pytest.mark.parametrize("simulate, says", [
    ("undermin=5", "simulate option 'undermin': caps simulate has no option --undermin "
                   "(its options with a value: layers, extent, undermine,"),
    ("undermine", "simulate: 'undermine' is not name=value (e.g. undermine=5)"),
    ("undermine=5;undermine=6", "simulate: 'undermine' is given twice"),
    ("undermine=10:0:5", "simulate option 'undermine': '10:0:5' needs start <= stop"),
    ("undermine=five", "simulate option 'undermine': 'five' is not a number"),
    ("steps=2.5", "simulate option 'steps': '2.5' is not a whole number"),
    ("material=neo hookean", "simulate option 'material': 'neo hookean' is not a word"),
    ("material=linear,a/b", "simulate option 'material': 'a/b' is not a word"),
    ("render=1", "simulate option 'render': --render is a flag"),
    ("mesh_size=2", "simulate option 'mesh_size': --mesh-size is set by the mesh_size column"),
    ("output=x", "simulate option 'output': --output is set by the workflow"),
])
def test_a_malformed_simulate_option_is_refused_naming_plan_and_option(options, simulate, says):
    with pytest.raises(ValueError, match=re.escape(f"plans table, plan 'z', {says}")):
        expand_plans({"z": {"parameters": "angle=45", "simulate": simulate}}, options)


def test_an_orientation_or_mesh_size_sweep_is_checked_like_a_parameter():
    with pytest.raises(ValueError, match=re.escape("plan 'z', orientation: '0:90:0' needs")):
        expand_plans({"z": {"orientation": "0:90:0"}})
    with pytest.raises(ValueError, match=re.escape("plan 'z', mesh_size: '2,,3' has an empty")):
        expand_plans({"z": {"mesh_size": "2,,3"}})
    with pytest.raises(ValueError, match="no list of caps simulate's options"):
        expand_plans({"z": {"simulate": "undermine=5"}})


def test_a_value_caps_refuses_is_refused_before_any_job_with_caps_message(options, caps):
    plans = expand_plans({"z": {"simulate": "undermine=0,5;material=linear,neo-hookan"},
                          "e": {"simulate": "rim=clamp;steps=0"}}, options)
    with pytest.raises(ValueError) as refused:
        check_simulate_values(caps, plans)
    lines = str(refused.value).splitlines()
    assert len(lines) == 3, lines
    assert any(l.startswith("plans table, plan 'z', simulate option 'material': caps simulate "
                            "refuses material=neo-hookan: caps: error: --material 'neo-hookan' "
                            "is unknown") for l in lines), lines
    assert any(l.startswith("plans table, plan 'e', simulate option 'rim': caps simulate "
                            "refuses rim=clamp: caps: error:") for l in lines), lines
    assert any("'steps': caps simulate refuses steps=0: caps: error: --steps 0" in l
               for l in lines), lines


def snakemake(*args, dry=True):
    exe = shutil.which("snakemake")
    if exe is None:
        pytest.skip("snakemake is not installed")
    if dry and not os.path.exists(CRANIUM):
        pytest.skip(f"{CRANIUM} is not installed (the cohort's third patient)")
    return subprocess.run([exe, *(["-n"] if dry else []), "-s", os.path.join(COHORT, "Snakefile"),
                           "--configfile", os.path.join(COHORT, "config.yaml"), *args],
                          capture_output=True, text=True)


def test_the_dry_run_of_the_sweep_table_has_one_simulation_per_patient_and_value(tmp_path, caps):
    run = snakemake("--config", f"plans={os.path.join(COHORT, 'plans_sweep.tsv')}",
                    f"caps={caps}", "--directory", str(tmp_path), "--cores", "2", "-p")
    assert run.returncode == 0, run.stdout + run.stderr
    counts = dict(re.findall(r"^(\w+) +(\d+) +\d+ +\d+$", run.stdout, re.M))
    # 3 patients (patients.tsv) x (5 angles + 2 lengths + 3 undermining + 3 prestretch) plans.
    assert counts["plan"] == "39" and counts["simulate"] == "39", counts
    assert counts["model"] == "3" and counts["table"] == "1", counts
    simulated = collections.Counter(
        re.findall(r"rule simulate:.*?wildcards: patient=\w+, plan=(\S+)", run.stdout, re.S))
    assert simulated == {p: 3 for p in [
        "z_angle30", "z_angle45", "z_angle60", "z_angle75", "z_angle90", "ellipse_length12",
        "ellipse_length15", "zu_undermine0", "zu_undermine5", "zu_undermine10", "ep_prestretch1",
        "ep_prestretch1.1", "ep_prestretch1.2"]}
    # Each plan is made and simulated with its own values (-p prints the commands).
    assert len(re.findall(r"plan new z-plasty .*--length 15 --angle 45 -o plans/\w+/z_angle45.json",
                          run.stdout)) == 3
    for plan, options in [("z_angle45", ""), ("zu_undermine5", " --undermine 5"),
                          ("ep_prestretch1.1", " --material neo-hookean --prestretch 1.1")]:
        assert len(re.findall(rf"simulate --model \S+ --plan plans/\w+/{re.escape(plan)}.json "
                              rf"-o \S+ --mesh-size 2.5{options} +-q --json", run.stdout)) == 3, plan


def test_a_simulate_option_caps_does_not_have_stops_the_workflow_before_any_job(tmp_path, caps):
    plans = tmp_path / "plans.tsv"
    plans.write_text("plan\ttemplate\tat\torientation\tparameters\tmesh_size\tsimulate\n"
                     "z\tz-plasty\t0,20\t90\tangle=45\t2.5\tundermining=0,5\n")
    run = snakemake("--config", f"plans={plans}", f"caps={caps}",
                    "--directory", str(tmp_path / "w"), "--cores", "1")
    assert run.returncode != 0
    assert ("plans table, plan 'z', simulate option 'undermining': caps simulate has no option "
            "--undermining (its options with a value: ") in run.stdout + run.stderr


def test_a_malformed_sweep_stops_the_workflow_before_any_job(tmp_path):
    plans = tmp_path / "plans.tsv"
    plans.write_text("plan\ttemplate\tat\torientation\tparameters\tmesh_size\n"
                     "z\tz-plasty\t0,20\t90\tangle=90:30:15\t2.5\n")
    run = snakemake("--config", f"plans={plans}", "--directory", str(tmp_path / "w"), "--cores", "1")
    assert run.returncode != 0
    assert "plan 'z', parameter 'angle': '90:30:15' needs start <= stop" in run.stdout + run.stderr


def test_two_undermining_values_give_two_forces_each_that_of_caps_simulate(tmp_path, caps):
    """A real run: the small face phantom, a Z-plasty undermined 5 and 15 mm, closed by the
    linear model on the clamped patch (material=linear;domain=patch: one solve each, and two
    options beside the sweep; the finite-strain closures took 34 s of this test's 37 s).
    results.tsv has the undermine column and two closing forces, different, each equal to
    `caps simulate --undermine X --material linear --domain patch` run by hand on the
    workflow's model and plan."""
    (tmp_path / "patients.tsv").write_text(
        "patient\tsource\tinput\toptions\n"
        "phantom\tphantom\t\t--face --scale 0.9 --voxels 88,88,84 --spacing 2.5,2.5,2.5\n")
    (tmp_path / "plans.tsv").write_text(
        "plan\ttemplate\tat\torientation\tparameters\tmesh_size\tsimulate\n"
        "zu\tz-plasty\tglabella+0,25\t90\tlength=15;angle=45\t2.5\t"
        "undermine=5,15;material=linear;domain=patch\n")
    work = tmp_path / "work"
    run = snakemake("--config", f"caps={caps}", f"patients={tmp_path / 'patients.tsv'}",
                    f"plans={tmp_path / 'plans.tsv'}", "--directory", str(work), "--cores", "2",
                    "results.tsv", dry=False)
    assert run.returncode == 0, run.stdout + run.stderr
    with open(work / "results.tsv") as f:
        rows = {r["plan"]: r for r in csv.DictReader(f, delimiter="\t")}
    assert list(rows) == ["zu_undermine5", "zu_undermine15"]
    direct = {}
    (tmp_path / "direct").mkdir()
    for plan, row in rows.items():
        assert row["status"] == "ok", row
        assert (row["undermine"], row["simulate"]) == (plan[len("zu_undermine"):],
                                                       f"undermine={row['undermine']};"
                                                       "material=linear;domain=patch")
        out = tmp_path / "direct" / plan
        subprocess.run([caps, "simulate", "--model", str(work / "models" / "phantom"),
                        "--plan", str(work / "plans" / "phantom" / f"{plan}.json"), "-o", str(out),
                        "--mesh-size", "2.5", "--undermine", row["undermine"], "--material",
                        "linear", "--domain", "patch", "-q"], check=True)
        with open(out / "result.json") as f:
            direct[plan] = json.load(f)["total_suture_force_n"]
        assert float(row["closing_force_n"]) == pytest.approx(direct[plan], rel=1e-9), plan
    assert abs(direct["zu_undermine5"] - direct["zu_undermine15"]) > 1e-3 * direct["zu_undermine5"]


def test_values_refused_only_together_are_asked_again_with_each_plans_own_options(tmp_path,
                                                                                   options):
    """A caps that refuses prestretch with the linear material (before the files): the check's
    first call mixes row a's material and row b's prestretch, which no plan has; only plan b2,
    which has both, is refused, with caps's message."""
    fake = tmp_path / "caps"
    fake.write_text('#!/bin/sh\ncase "$*" in *"--material linear"*"--prestretch 1.1"*)\n'
                    '  echo "caps: error: prestretch needs neo-hookean" >&2; exit 2;;\nesac\n'
                    'echo "caps: error: $3: no such file or folder" >&2; exit 2\n')
    fake.chmod(0o755)
    plans = expand_plans({"a": {"simulate": "material=linear"},
                          "b": {"simulate": "material=neo-hookean;prestretch=1.1"}}, options)
    check_simulate_values(str(fake), plans)
    plans = expand_plans({"a": {"simulate": "material=linear"},
                          "b": {"simulate": "material=neo-hookean,linear;prestretch=1.1"}},
                         options)
    with pytest.raises(ValueError) as refused:
        check_simulate_values(str(fake), plans)
    assert str(refused.value) == ("plans table, plan 'b_materiallinear': caps simulate refuses "
                                  "material=linear;prestretch=1.1: caps: error: prestretch "
                                  "needs neo-hookean")


def test_a_lesion_is_given_by_its_diameter_or_its_outline_in_mm_one_of_the_two():
    assert lesion_shape({"lesion": "a", "diameter": "6"}) == ["--diameter", "6"]
    hexagon = "3,0;1.5,2.6;-1.5,2.6;-3,0;-1.5,-2.6;1.5,-2.6"
    assert lesion_shape({"lesion": "a", "diameter": "", "outline_mm": hexagon}) == \
        ["--outline-mm", hexagon]
    for row, words in [({"lesion": "a", "diameter": "6", "outline_mm": hexagon}, "one of the two"),
                       ({"lesion": "a", "diameter": " ", "outline_mm": ""}, "one of the two"),
                       ({"lesion": "a"}, "lesion 'a'"),
                       ({"lesion": "a", "diameter": "six"}, "'six' is not a number"),
                       ({"lesion": "a", "outline_mm": "1,0;0,1;'$(rm x)'"}, "not LEFT,UP")]:
        with pytest.raises(ValueError, match=words):
            lesion_shape(row)

