"""The Python package over the app layer: a model, a plan and a simulation through Python equal
the caps program's on the same inputs; maps and results arrive as numpy arrays of the documented
shapes; errors arrive as the documented exception types with the caps message."""

import json
import warnings

import numpy as np
import pytest

import caps


def test_every_verb_has_its_defaults():
    assert "simulate" in caps.verbs() and "plan_new" in caps.verbs()
    d = caps.defaults("simulate")
    assert d["mesh_size"] > 0 and d["material"] in ("linear", "neo-hookean")
    assert caps.defaults("model from-volume") == caps.defaults("model_from_volume")


def test_every_verb_of_the_program_is_callable_from_python(cli):
    # The list is the program's own (app's list of verbs), not one kept here.
    names = caps.verbs()
    words = caps._caps.command_line_names()
    assert len(names) == len(words) == len(set(names))
    assert "compare_models" in names and "model_sensitivity" in names
    for name, spelled in zip(names, words):
        assert name == spelled.replace(" ", "_").replace("-", "_")
        # The program has the verb, with the same help.
        c = cli(*spelled.split(), "--help")
        assert c.returncode == 0, (spelled, c.stderr)
        assert c.stdout.startswith(caps.verb_help(name) + "\n"), spelled
        # Python reaches the verb's request: its defaults, and an empty request is refused for
        # the field it lacks (or, with none required, runs).
        assert isinstance(caps.defaults(name), dict)
        assert caps.defaults(spelled) == caps.defaults(name)
        try:
            caps.run(spelled, {})
        except caps.InvalidInput as e:
            assert "is required" in str(e), (name, str(e))
        else:
            assert not [k for k, v in caps.defaults(name).items() if v == ""], name


def test_the_sensitivity_map_through_python_equals_the_cli(model, work, cli):
    # A verb Python lacked while it kept its own list: one plan centre, the linear model.
    args = {"theta": "0,0,15", "z": "60,60,10", "thickness": 5, "mesh_size": 3, "threads": 1,
            "material": "linear"}
    py = caps.model_sensitivity(model, work / "sens_py", **args)
    flags = [x for k, v in args.items() for x in ("--" + k.replace("_", "-"), str(v))]
    c = cli("model", "sensitivity", model, "-o", work / "sens_cli", *flags, "-q", "--json")
    assert c.returncode == 0, c.stdout + c.stderr
    from_cli = json.loads(c.stdout)
    assert py["planned"] == 1 and py["constant_thickness_mm"] == 5
    for r in (py, from_cli):
        del r["output"], r["timings_s"]
    assert py == from_cli


def test_model_maps_are_numpy_arrays_on_the_grid(model):
    m = caps.load_model(model)
    assert m["info"]["grid"]["n_theta"] == 128 and m["info"]["grid"]["n_z"] == 64
    for name in ("r_skin", "r_bone", "thickness", "thickness_normal"):
        assert m[name].shape == (64, 128) and m[name].dtype == np.float32
        assert np.isfinite(m[name]).all()
    for name in ("valid", "measured_skin", "measured_bone"):
        assert m[name].shape == (64, 128) and m[name].dtype == np.bool_
    assert m["flags"].dtype == np.uint8
    np.testing.assert_array_equal(m["valid"], m["flags"] == 0)
    assert m["theta_deg"].shape == (128,) and m["z_mm"].shape == (64,)
    assert m["theta_deg"][0] == pytest.approx(-180.0)
    assert m["theta_deg"][1] - m["theta_deg"][0] == pytest.approx(360.0 / 128)
    # thickness = r_skin - r_bone, and the phantom's soft tissue is 2.5 .. 8.5 mm thick
    np.testing.assert_allclose(m["thickness"], m["r_skin"] - m["r_bone"], atol=1e-4)
    t = m["thickness"][m["valid"]]
    assert t.size > 0.3 * m["valid"].size
    assert 2.5 - 1.25 < np.median(t) < 8.5 + 1.25
    np.testing.assert_allclose(m["axis"]["direction"], [0, 0, 1], atol=1e-6)


def test_a_simulation_through_python_equals_the_cli(model, work, cli):
    plan = work / "vy.json"
    planned = caps.plan_new("v-y-advancement", model=model, output=plan, at="0,60",
                            orientation=90, parameters={"length": 12, "advance": 3})
    assert planned["ok"] and planned["suture_quadruples"]  # the plan file with its check
    assert caps.plan_check(plan)["suture_quadruples"] == planned["suture_quadruples"]

    steps = []
    sim = caps.simulate(model, plan, work / "sim_py", mesh_size=2.5, undermine=4,
                        progress=lambda step, fraction: steps.append((step, fraction)))
    assert steps and all(0.0 <= f <= 1.0 for _, f in steps)
    assert sim["closing_force_n"] > 0

    c = cli("simulate", "--model", model, "--plan", plan, "-o", work / "sim_cli",
            "--mesh-size", "2.5", "--undermine", "4", "-q", "--json")
    assert c.returncode == 0, c.stdout + c.stderr
    with open(work / "sim_cli" / "result.json") as f:
        cli_result = json.load(f)
    assert sim["closing_force_n"] == pytest.approx(cli_result["total_suture_force_n"],
                                                   rel=0, abs=1e-9)
    assert sim["max_displacement_mm"] == pytest.approx(cli_result["max_displacement_mm"],
                                                       rel=0, abs=1e-9)

    r = caps.read_result(work / "sim_py")
    n = sim["nodes"]
    assert r["nodes"].shape == (n, 3) and r["displacement"].shape == (n, 3)
    assert r["max_principal_mpa"].shape == (n,)
    assert np.linalg.norm(r["displacement"], axis=1).max() == pytest.approx(
        sim["max_displacement_mm"], rel=1e-9)
    assert r["result"]["total_suture_force_n"] == sim["closing_force_n"]


def test_a_suggestion_ranks_the_designs_around_a_lesion(model, work):
    # Every 90 deg on the clamped patch with the linear model: the cheapest closures.
    s = caps.plan_suggest(model, "0,60", 4, work / "suggest", margin=1, step=90, refine=0,
                          domain="patch", material="linear")
    ranked = [d for d in s["designs"] if d["rank"] > 0]
    assert s["best"] == ranked[0]["name"] and len(s["designs"]) == 2  # ellipses at 0 and 90
    forces = [d["objective"] for d in ranked]
    assert forces == sorted(forces) and forces[0] > 0
    assert (work / "suggest" / "suggestions.png").exists()
    with pytest.raises(caps.InvalidParameter, match="diameter 0"):
        caps.plan_suggest(model, "0,60", 0, work / "refused")
    assert not (work / "refused").exists()
    # A lesion drawn as its outline (a diamond 6 mm of z tall, 2 deg wide): its centre and size
    # its own (7.0 mm from top to bottom on the skin, where the forehead slopes back).
    s = caps.plan_suggest(model, output=work / "outline", outline="0,57;1,60;0,63;-1,60",
                          margin=1, step=90, refine=0, domain="patch", material="linear",
                          objective="excised")
    assert s["lesion"]["outline_theta_z"][0] == [0, 57] and abs(s["lesion"]["z_mm"] - 60) < 0.01
    assert 6.8 < s["lesion"]["diameter_mm"] < 7.2 and s["best"] == "ellipse-000"
    # The same shape in mm about its centre (left, up along the skin): one lesion for any patient.
    s = caps.plan_suggest(model, "0,60", output=work / "outline_mm",
                          outline_mm="0,-3.5;1.7,0;0,3.5;-1.7,0", margin=1, step=90, refine=0,
                          domain="patch", material="linear", objective="excised")
    top = s["lesion"]["outline_theta_z"][2]
    assert abs(top[0]) < 1e-6 and top[1] > 62 and abs(s["lesion"]["z_mm"] - 60) < 1e-9
    assert 6.9 < s["lesion"]["diameter_mm"] < 7.1 and s["best"] == "ellipse-000"
    with pytest.raises(caps.InvalidParameter, match="give the centre too"):
        caps.plan_suggest(model, output=work / "refused", outline_mm="0,-3.5;1.7,0;0,3.5")


def test_skin_lines_need_the_nose_the_phantom_has_not(model):
    # The plain phantom has no nasion or subnasale: no line, and why (the face phantom's lines:
    # tests/test_server.cpp; Cranium's: planner_e2e_cranium).
    lines = caps.plan_skin_lines(model, spacing_mm=12)
    assert lines["count"] == 0 and lines["lines"] == []
    assert "nasion" in lines["note"] and "Borges" in lines["source"]
    with pytest.raises(caps.InvalidParameter, match="spacing 1 mm"):
        caps.plan_skin_lines(model, spacing_mm=1)


def test_the_generic_run_takes_the_request_json(model, work):
    body = {"procedure": "ellipse", "model": str(model), "at": "0,60", "orientation": 90,
            "parameters": {"length": 15, "width": 4}, "output": str(work / "ellipse.json")}
    r = caps.run("plan new", body)
    assert r["procedure"]["name"] == "ellipse" and r["check"]["cut_length_mm"] > 0
    assert caps.run("plan_new", body, force=True) == r  # keyword fields join the dict


def test_warnings_reach_python_and_the_result(model, work):
    # docs/plan-format.md's hand-written Z, with its central limb left unsutured
    procedure = {"format": "caps-procedure", "format_version": 1, "name": "open-z",
                 "points_mm": [[-2.5, 17.3], [-10, 0], [10, 0], [2.5, -17.3]],
                 "paths": [[0, 1, 2, 3]], "excisions": [],
                 "sutures": [[[5, 0], [5, 4]], [[2, 1], [2, 3]]], "notes": ""}
    (work / "open_z.json").write_text(json.dumps(procedure))
    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        r = caps.plan_new(work / "open_z.json", model=model, output=work / "open_z_plan.json",
                          at="0,60", orientation=90)
    got = [str(w.message) for w in seen if issubclass(w.category, caps.CapsWarning)]
    assert any("not sutured" in w for w in r["check"]["warnings"]), r["check"]
    assert got == r["check"]["warnings"]


def test_errors_are_python_exceptions_with_the_cli_message(model, work, cli):
    with pytest.raises(caps.InvalidInput) as e:
        caps.simulate(model, work / "none.json", work / "x", mesh_sise=2)
    assert isinstance(e.value, ValueError)
    assert 'unknown key "mesh_sise"' in str(e.value)

    with pytest.raises(caps.IoError) as e:
        caps.plan_check(work / "missing_plan.json")
    assert isinstance(e.value, OSError)
    c = cli("plan", "check", work / "missing_plan.json")
    assert c.returncode == 2 and str(e.value) in c.stdout + c.stderr

    with pytest.raises(caps.InvalidParameter) as e:
        caps.plan_new("ellipse", model=model, output=work / "both.json", at="0,60",
                      parameters={"width": 10, "apex_angle": 30})
    assert isinstance(e.value, ValueError)
    assert str(e.value) == "ellipse: give width or apex_angle, not both (the one sets the other)"
    assert not (work / "both.json").exists()

    with pytest.raises(caps.InvalidInput, match="no verb"):
        caps.run("simulte", {})
    with pytest.raises(TypeError):
        caps.run("plan_check", plan=object())
    assert issubclass(caps.SolverError, RuntimeError) and issubclass(caps.SolverError, caps.Error)


def test_a_progress_callback_that_raises_stops_the_run(model, work):
    caps.plan_new("ellipse", model=model, output=work / "stop.json", at="0,60", orientation=90,
                  parameters={"length": 15, "width": 4})

    class Stop(Exception):
        pass

    def stop(step, fraction):
        raise Stop(step)

    with pytest.raises(Stop):
        caps.simulate(model, work / "stop.json", work / "stopped", mesh_size=2.5, progress=stop)
    assert not (work / "stopped").exists()


def test_a_mesh_inverted_before_any_load_is_a_bad_input_naming_the_element(work, cli):
    # the box of caps fem box, mirrored in x: every element is inverted (a damaged file, not a
    # failed solve: issue 36)
    box = work / "inverted_box"
    caps.run("fem_box", output=box, cells="2,1,1")
    vtu = (box / "mesh.vtu").read_text()
    head, rest = vtu.split("<Points>", 1)
    points, tail = rest.split("</Points>", 1)
    opening, values = points.split(">", 1)
    values, closing = values.split("</DataArray>", 1)
    xyz = np.array(values.split(), dtype=float).reshape(-1, 3)
    xyz[:, 0] *= -1
    values = "\n" + "\n".join(" ".join(repr(v) for v in row) for row in xyz) + "\n"
    (box / "mesh.vtu").write_text(
        head + "<Points>" + opening + ">" + values + "</DataArray>" + closing + "</Points>" + tail)

    with pytest.raises(caps.InvalidInput) as e:
        caps.run("solve", mesh=box, output=work / "inverted_out")
    assert isinstance(e.value, ValueError)
    assert "element 0" in str(e.value) and "Jacobian determinant" in str(e.value)
    assert not (work / "inverted_out").exists()
    c = cli("solve", box, "-o", work / "inverted_cli")
    assert c.returncode == 2 and str(e.value) in c.stdout + c.stderr


def test_a_local_chart_faces_the_skin_at_its_point(model, work):
    # The chart's centre (theta 0, z 0) is the parent's skin point at "20,60", its axis behind it.
    chart = work / "chart"
    r = caps.model_chart(model, "20,60", chart, radius=50, force=True)
    source = r["source"]["chart"]
    assert source["at"] == "20,60" and source["radius_mm"] == 50
    parent = caps.model_site(model, "20,60")
    centre = caps.model_site(chart, "0,0")
    gap = sum((a - b) ** 2 for a, b in zip(parent["lps"], centre["lps"])) ** 0.5
    assert gap < 1.5, gap  # the phantom's 2.5 mm voxels
    with pytest.raises(caps.InvalidInput, match="itself a chart"):
        caps.model_chart(chart, "0,0", work / "chart2")
