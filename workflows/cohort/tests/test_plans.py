"""The plans table's sweeps (workflows/cohort/plans.py): the values a sweep gives, the plan ids
and parameters it expands to, its refusals, and the workflow's dry run over plans_sweep.tsv
(one plan and one simulation per patient and value)."""

import collections
import os
import re
import shutil
import subprocess
import sys

import pytest

HERE = os.path.dirname(os.path.abspath(__file__))
COHORT = os.path.dirname(HERE)
sys.path.insert(0, COHORT)

from plans import expand_plans, plan_options, sweep_values  # noqa: E402

CRANIUM = "/usr/share/doc/invesalius-examples/examples/Cranium.inv3"


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


def snakemake(*args):
    exe = shutil.which("snakemake")
    if exe is None:
        pytest.skip("snakemake is not installed")
    if not os.path.exists(CRANIUM):
        pytest.skip(f"{CRANIUM} is not installed (the cohort's third patient)")
    return subprocess.run([exe, "-n", "-s", os.path.join(COHORT, "Snakefile"),
                           "--configfile", os.path.join(COHORT, "config.yaml"), *args],
                          capture_output=True, text=True)


def test_the_dry_run_of_the_sweep_table_has_one_simulation_per_patient_and_value(tmp_path):
    run = snakemake("--config", f"plans={os.path.join(COHORT, 'plans_sweep.tsv')}",
                    "--directory", str(tmp_path), "--cores", "2", "-p")
    assert run.returncode == 0, run.stdout + run.stderr
    counts = dict(re.findall(r"^(\w+) +(\d+) +\d+ +\d+$", run.stdout, re.M))
    # 3 patients (patients.tsv) x (5 angles + 2 lengths) plans.
    assert counts["plan"] == "21" and counts["simulate"] == "21", counts
    assert counts["model"] == "3" and counts["table"] == "1", counts
    simulated = collections.Counter(
        re.findall(r"rule simulate:.*?wildcards: patient=\w+, plan=(\S+)", run.stdout, re.S))
    assert simulated == {p: 3 for p in ["z_angle30", "z_angle45", "z_angle60", "z_angle75",
                                        "z_angle90", "ellipse_length12", "ellipse_length15"]}
    # Each plan is made with its own value (-p prints the commands).
    assert len(re.findall(r"plan new z-plasty .*--length 15 --angle 45 -o plans/\w+/z_angle45.json",
                          run.stdout)) == 3


def test_a_malformed_sweep_stops_the_workflow_before_any_job(tmp_path):
    plans = tmp_path / "plans.tsv"
    plans.write_text("plan\ttemplate\tat\torientation\tparameters\tmesh_size\n"
                     "z\tz-plasty\t0,20\t90\tangle=90:30:15\t2.5\n")
    run = snakemake("--config", f"plans={plans}", "--directory", str(tmp_path / "w"), "--cores", "1")
    assert run.returncode != 0
    assert "plan 'z', parameter 'angle': '90:30:15' needs start <= stop" in run.stdout + run.stderr
