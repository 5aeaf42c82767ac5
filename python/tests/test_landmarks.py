"""Landmarks through Python: caps.load_model returns the landmarks model.json holds (the same as
`caps model landmarks --json`), a plan placed at a landmark through Python equals the caps
program's, and an absent landmark is caps.InvalidInput."""

import json

import pytest

import caps


@pytest.fixture(scope="session")
def face_model(work):
    ct = work / "face.nii.gz"
    caps.phantom(ct, voxels="96,96,90", spacing="2.5,2.5,2.5", face=True)
    out = work / "face"
    caps.model_from_volume(ct, out, n_theta=256, n_z=128)
    return out


def test_load_model_returns_the_landmarks(face_model, cli):
    m = caps.load_model(face_model)
    lm = m["landmarks"]
    assert set(lm) == {"glabella", "nasion", "pronasale", "subnasale", "pogonion",
                       "zygion_left", "zygion_right", "exocanthion_left", "exocanthion_right",
                       "tragion_left", "tragion_right"}
    assert lm["glabella"]["found"] and lm["pronasale"]["found"]
    # The face phantom's glabella is 28 mm above the axis point (2, 6, 0), on the midline, and
    # its nose tip in front of it near z = -12 mm (phantom.hpp; 2.5 mm voxels: within 2 mm).
    g = lm["glabella"]["lps"]
    assert g[0] == pytest.approx(2.0, abs=2.0) and g[2] == pytest.approx(27.5, abs=2.5)
    assert lm["pronasale"]["lps"][1] < g[1] - 10  # the nose tip is anterior (-y) of the brow
    assert lm["zygion_left"]["lps"][0] > 40 > -40 > lm["zygion_right"]["lps"][0]  # L is +x
    assert 2.0 < lm["glabella"]["thickness_mm"] < 15.0
    # The same as the caps program's.
    c = cli("model", "landmarks", face_model, "--no-write", "--json")
    assert c.returncode == 0, c.stdout + c.stderr
    assert json.loads(c.stdout)["items"]["glabella"]["lps"] == g
    assert caps.model_landmarks(face_model, write=False)["glabella"]["lps"] == g


def test_plan_at_a_landmark_equals_the_cli(face_model, work, cli):
    planned = caps.plan_new("ellipse", model=face_model, output=work / "gl.json",
                            at="glabella+10,15", orientation=90)
    assert planned["at"]["landmark"] == "glabella"
    c = cli("plan", "new", "ellipse", "--model", face_model, "--at", "glabella+10,15",
            "--orientation", "90", "-o", work / "gl_cli.json", "-q")
    assert c.returncode == 0, c.stdout + c.stderr
    with open(work / "gl_cli.json") as f:
        assert json.load(f)["frame"] == planned["frame"]
    site = caps.model_site(face_model, "glabella+10,15")
    assert site["theta_deg"] == pytest.approx(planned["frame"]["theta_deg"], abs=1e-9)
    assert site["thickness_mm"] > 0


def test_an_absent_landmark_is_invalid_input(model):
    # The plain phantom has no brow: no glabella.
    with pytest.raises(caps.InvalidInput, match="has no glabella"):
        caps.model_site(model, "glabella+0,0")
    assert caps.load_model(model)["landmarks"]["glabella"]["found"] is False
