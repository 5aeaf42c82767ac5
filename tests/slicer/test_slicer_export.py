"""`caps model export-slicer` read back by readers that are not caps's (docs/slicer.md, "What
was checked").

On the analytic phantom (layered soft tissue, a face of landmarks; 2.5 mm voxels) and on the
same phantom written on an oblique grid (rotated 12 deg about S and 6 deg about L, as nibabel
writes it), the exported folder is read with VTK's readers (Debian python3-vtk9:
vtkNrrdReader, vtkPolyDataReader, vtkPLYReader, vtkXMLUnstructuredGridReader), nibabel (the
source CT), a header parser of this file, and jsonschema (python3-jsonschema) against Slicer's
markups schema (tests/data/slicer/). Positions are compared with caps's own answers (`caps
volume info`, `caps model site`, `caps model landmarks`, the model's PLY surfaces, `caps
render`) to within 0.1 mm or better.

Run by ctest (tests/CMakeLists.txt, CAPS_EXE set) with Debian's python3.
"""

import glob
import gzip
import json
import math
import os
import shutil
import subprocess

import numpy as np
import pytest

# VTK's modules one by one: `import vtk` would load the parallel I/O module, whose factory
# replaces vtkNrrdReader by an MPI reader that needs a controller.
pytest.importorskip("vtkmodules.vtkIOImage")
jsonschema = pytest.importorskip("jsonschema")
nibabel = pytest.importorskip("nibabel")
from vtkmodules.util.numpy_support import vtk_to_numpy  # noqa: E402
from vtkmodules.vtkCommonCore import reference  # noqa: E402
from vtkmodules.vtkCommonDataModel import vtkCellLocator  # noqa: E402
from vtkmodules.vtkIOImage import vtkNrrdReader  # noqa: E402
from vtkmodules.vtkIOLegacy import vtkPolyDataReader  # noqa: E402
from vtkmodules.vtkIOPLY import vtkPLYReader  # noqa: E402
from vtkmodules.vtkIOXML import vtkXMLUnstructuredGridReader  # noqa: E402

CAPS = os.environ.get("CAPS_EXE", "caps")
HERE = os.path.dirname(os.path.abspath(__file__))
SCHEMA = os.path.join(HERE, "..", "data", "slicer", "markups-schema-v1.0.3.json")


def run(*args, cwd, check=True):
    p = subprocess.run([CAPS, *args], cwd=cwd, capture_output=True, text=True)
    if check and p.returncode != 0:
        raise AssertionError(f"caps {' '.join(args)}: exit {p.returncode}\n{p.stderr}")
    return p


def rotation(axis, deg):
    a = math.radians(deg)
    c, s = math.cos(a), math.sin(a)
    if axis == 0:
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


@pytest.fixture(scope="module")
def work(tmp_path_factory):
    d = tmp_path_factory.mktemp("slicer")
    run("phantom", "-o", "ct.nii.gz", "--voxels", "96,96,90", "--spacing", "2.5,2.5,2.5",
        "--face", "--layered", "-q", cwd=d)
    # The same CT on an oblique grid: the affine turned about the head's centre.
    img = nibabel.load(str(d / "ct.nii.gz"))
    a = img.affine.copy()
    centre = a @ np.array([47.5, 47.5, 44.5, 1.0])
    r = rotation(2, 12.0) @ rotation(0, 6.0)
    m = np.eye(4)
    m[:3, :3] = r
    m[:3, 3] = centre[:3] - r @ centre[:3]
    oblique = nibabel.Nifti1Image(np.asanyarray(img.dataobj), m @ a)
    oblique.set_sform(m @ a, code=1)
    oblique.set_qform(m @ a, code=1)
    nibabel.save(oblique, str(d / "oblique.nii.gz"))
    shutil.copy(d / "ct.nii.gz", d / "gone.nii.gz")
    for src, model in (("ct.nii.gz", "m"), ("oblique.nii.gz", "mo"), ("gone.nii.gz", "mg")):
        run("model", "from-volume", src, "-o", model, "--n-theta", "128", "--n-z", "64",
            "--no-tissue", "-q", cwd=d)
    os.remove(d / "gone.nii.gz")
    run("plan", "new", "ellipse", "--model", "m", "--at", "glabella+0,25", "-o", "e.json", "-q",
        cwd=d)
    run("plan", "new", "ellipse", "--model", "mo", "--at", "12,40", "-o", "eo.json", "-q", cwd=d)
    run("simulate", "--model", "m", "--plan", "e.json", "-o", "esim", "-q", cwd=d)
    out = json.loads(run("model", "export-slicer", "m", "--plan", "e.json", "--result", "esim",
                         "-o", "s", "--json", "-q", cwd=d).stdout)
    out_o = json.loads(run("model", "export-slicer", "mo", "-o", "so", "--json", "-q",
                           cwd=d).stdout)
    return {"dir": d, "s": out, "so": out_o}


# ---- NRRD -------------------------------------------------------------------------------------

def nrrd_header(path):
    """The header fields (key: value) and key/value pairs (key:=value) of an attached NRRD."""
    fields, pairs = {}, {}
    with open(path, "rb") as f:
        magic = f.readline().decode().strip()
        assert magic.startswith("NRRD000"), magic
        for raw in f:
            line = raw.decode("latin-1").rstrip("\n")
            if line == "":
                break
            if line.startswith("#"):
                continue
            if ":=" in line:
                k, v = line.split(":=", 1)
                pairs[k] = v
            else:
                k, v = line.split(": ", 1)
                fields[k] = v
    return fields, pairs


def vectors(text):
    return np.array([[float(x) for x in t.strip("()").split(",")] for t in text.split()])


def nrrd_geometry(fields):
    """(sizes, D with columns = space directions, origin) in LPS mm."""
    assert fields["space"] == "left-posterior-superior"
    sizes = [int(x) for x in fields["sizes"].split()]
    d = vectors(fields["space directions"]).T
    o = vectors(fields["space origin"])[0]
    return sizes, d, o


def vtk_image(path):
    r = vtkNrrdReader()
    r.SetFileName(str(path))
    r.Update()
    im = r.GetOutput()
    nx, ny, nz = im.GetDimensions()
    a = vtk_to_numpy(im.GetPointData().GetScalars()).reshape(nz, ny, nx)
    return im, a


@pytest.mark.parametrize("folder,source", [("s", "ct.nii.gz"), ("so", "oblique.nii.gz")])
def test_ct_is_in_patient_lps_where_caps_and_nibabel_put_each_voxel(work, folder, source):
    d = work["dir"]
    path = d / folder / "ct.nrrd"
    fields, _ = nrrd_header(path)
    assert fields["encoding"] == "gzip" and fields["kinds"] == "domain domain domain"
    sizes, dmat, origin = nrrd_geometry(fields)
    # caps's own geometry of the source (LPS)
    info = json.loads(run("volume", "info", source, "--json", cwd=d).stdout)
    assert sizes == info["dims"]
    caps_d = np.array(info["direction_columns"]).T * np.array(info["spacing_mm"])
    assert np.abs(dmat - caps_d).max() < 1e-6
    assert np.abs(origin - np.array(info["origin_lps"])).max() < 1e-6
    # VTK reads the same grid (it keeps no direction: spacing = the columns' lengths)
    im, a = vtk_image(path)
    assert list(im.GetDimensions()) == sizes
    assert np.allclose(im.GetSpacing(), np.linalg.norm(dmat, axis=0), atol=1e-6)
    assert np.allclose(im.GetOrigin(), origin, atol=1e-6)
    # nibabel's voxels (RAS affine) land on the NRRD's voxel of the same value at the same
    # patient position: LPS = diag(-1, -1, 1) RAS.
    img = nibabel.load(str(d / source))
    data = np.asanyarray(img.dataobj)
    rng = np.random.default_rng(38)
    flip = np.diag([-1.0, -1.0, 1.0])
    inv = np.linalg.inv(dmat)
    worst = 0.0
    checked = 0
    for ijk in rng.integers(0, data.shape, size=(400, 3)):
        ras = img.affine @ np.append(ijk, 1.0)
        lps = flip @ ras[:3]
        idx = inv @ (lps - origin)
        near = np.rint(idx)
        worst = max(worst, np.linalg.norm(dmat @ (idx - near)))  # mm
        i, j, k = near.astype(int)
        assert a[k, j, i] == pytest.approx(float(data[tuple(ijk)]), abs=1e-3)
        checked += 1
    assert checked == 400 and worst < 0.01  # every voxel within 0.01 mm of where nibabel puts it


def test_segmentation_follows_slicers_conventions_and_the_tissue(work):
    d = work["dir"]
    fields, pairs = nrrd_header(d / "s" / "tissue.seg.nrrd")
    ct_fields, _ = nrrd_header(d / "s" / "ct.nrrd")
    for k in ("sizes", "space", "space directions", "space origin"):
        assert fields[k] == ct_fields[k], k  # on the CT's grid
    assert fields["type"] == "unsigned char" and fields["dimension"] == "3"
    assert pairs["Segmentation_MasterRepresentation"] == "Binary labelmap"
    assert pairs["Segmentation_ReferenceImageExtentOffset"] == "0 0 0"
    segs = {}
    n = 0
    while f"Segment{n}_ID" in pairs:
        for key in ("Name", "LabelValue", "Layer", "Color", "Extent"):
            assert f"Segment{n}_{key}" in pairs, (n, key)
        segs[pairs[f"Segment{n}_ID"]] = {
            "name": pairs[f"Segment{n}_Name"], "label": int(pairs[f"Segment{n}_LabelValue"]),
            "layer": int(pairs[f"Segment{n}_Layer"]),
            "extent": [int(x) for x in pairs[f"Segment{n}_Extent"].split()],
            "color": [float(x) for x in pairs[f"Segment{n}_Color"].split()]}
        n += 1
    assert set(segs) == {"dermis", "fat", "deep", "bone"}
    assert segs["dermis"]["name"] == "skin (dermis)" and segs["bone"]["name"] == "bone"
    assert len({s["label"] for s in segs.values()}) == 4
    assert all(s["layer"] == 0 and all(0 <= c <= 1 for c in s["color"]) for s in segs.values())
    _, lab = vtk_image(d / "s" / "tissue.seg.nrrd")
    _, ct = vtk_image(d / "s" / "ct.nrrd")
    assert set(np.unique(lab)) <= {0} | {s["label"] for s in segs.values()}
    summary = json.loads(open(d / "s" / "summary.json").read())
    listed = {s["id"]: s for s in summary["segmentation"]}
    assert summary["frame"] == "LPS"
    for sid, s in segs.items():
        k, j, i = np.nonzero(lab == s["label"])
        assert listed[sid]["label"] == s["label"] and listed[sid]["name"] == s["name"]
        assert len(i) == listed[sid]["voxels"] > 0, sid
        assert s["extent"] == [i.min(), i.max(), j.min(), j.max(), k.min(), k.max()], sid
    # The tissue under each label, in the CT: bone is bone (the model's 250 HU threshold on
    # block means), and the layered phantom's fat (-100 HU) is below caps's fat level (-30 HU)
    # and well below the muscle (+45) under it, which partial volume blurs but does not reorder.
    # (Its dermis, 1.4-2.2 mm under the skin, shares 2.5 mm voxels with the air outside: no
    # check of its CT number here.)
    mean = {sid: ct[lab == s["label"]].mean() for sid, s in segs.items()}
    assert np.mean(ct[lab == segs["bone"]["label"]] > 250) > 0.8
    assert mean["fat"] < -30 and mean["fat"] < mean["deep"] - 50


# ---- surfaces ---------------------------------------------------------------------------------

def poly(path):
    r = vtkPolyDataReader()
    r.SetFileName(str(path))
    r.ReadAllScalarsOn()
    r.ReadAllVectorsOn()
    r.ReadAllFieldsOn()
    r.Update()
    return r, r.GetOutput()


def ply(path):
    r = vtkPLYReader()
    r.SetFileName(str(path))
    r.Update()
    return r.GetOutput()


def points(pd):
    return vtk_to_numpy(pd.GetPoints().GetData()).astype(float)


def array(pd, name):
    a = pd.GetPointData().GetArray(name)
    assert a is not None, name
    return vtk_to_numpy(a).astype(float)


def cylindrical(model_json, p):
    ax = model_json["axis"]
    o, d, f = (np.array(ax[k]) for k in ("origin_lps", "direction", "front"))
    left = np.cross(d, f)
    v = p - o
    z = v @ d
    rad = v - z * d
    return math.degrees(math.atan2(rad @ left, rad @ f)), z


def test_skin_and_bone_are_the_models_surfaces_with_its_thickness(work):
    d = work["dir"]
    reader, skin = poly(d / "s" / "skin.vtk")
    assert "SPACE=LPS" in reader.GetHeader()
    ref = ply(d / "m" / "skin.ply")
    assert skin.GetNumberOfPoints() == ref.GetNumberOfPoints() > 1000
    assert skin.GetNumberOfCells() == ref.GetNumberOfCells()
    assert np.abs(points(skin) - points(ref)).max() < 1e-3  # mm (float32 of caps's doubles)
    assert skin.GetPointData().GetScalars().GetName() == "thickness_normal_mm"
    tn, tr = array(skin, "thickness_normal_mm"), array(skin, "thickness_radial_mm")
    measured = array(skin, "thickness_measured")
    layers = sum(array(skin, n) for n in ("dermis_normal_mm", "fat_normal_mm", "deep_normal_mm"))
    assert np.abs(layers - tn).max() < 1e-3  # the layers along the normal add up to it
    mj = json.load(open(d / "m" / "model.json"))
    p = points(skin)
    rng = np.random.default_rng(7)
    picked = [i for i in rng.permutation(len(p)) if measured[i] == 1][:10]
    assert len(picked) == 10
    for i in picked:
        theta, z = cylindrical(mj, p[i])
        site = json.loads(run("model", "site", "m", f"--at={float(theta)!r},{float(z)!r}", "--json",
                              cwd=d).stdout)
        assert tn[i] == pytest.approx(site["thickness_mm"], abs=2e-3)
        assert tr[i] == pytest.approx(site["thickness_radial_mm"], abs=2e-3)
        # the surface's vertex and caps's skin point at its (theta, z): the isosurface and the
        # range image of one skin
        assert np.linalg.norm(np.array(site["lps"]) - p[i]) < 1.5
    reader, bone = poly(d / "s" / "bone.vtk")
    assert "SPACE=LPS" in reader.GetHeader()
    ref = ply(d / "m" / "bone.ply")
    assert np.abs(points(bone) - points(ref)).max() < 1e-3
    on = array(bone, "on_base")
    bt = array(bone, "thickness_normal_mm")
    assert on.sum() > 100
    assert np.isfinite(bt[on == 1]).all() and np.isnan(bt[on == 0]).all()


@pytest.mark.parametrize("folder", ["s", "so"])
def test_skin_surface_sits_on_the_ct_skin_in_one_frame(work, folder):
    # The CT (its NRRD grid, read by VTK) sampled at the skin surface's points and 4 mm out and in
    # along the model's radial ray: air outside, tissue inside, the edge between. A surface and
    # volume in different frames (RAS against LPS, or the oblique grid's rotation lost) fail.
    d = work["dir"]
    model = "m" if folder == "s" else "mo"
    fields, _ = nrrd_header(d / folder / "ct.nrrd")
    sizes, dmat, origin = nrrd_geometry(fields)
    _, ct = vtk_image(d / folder / "ct.nrrd")
    inv = np.linalg.inv(dmat)
    _, skin = poly(d / folder / "skin.vtk")
    p = points(skin)[::7]
    ax = json.load(open(d / model / "model.json"))["axis"]
    o, a = np.array(ax["origin_lps"]), np.array(ax["direction"])
    radial = (p - o) - np.outer((p - o) @ a, a)
    radial /= np.linalg.norm(radial, axis=1)[:, None]

    def sample(q):
        idx = np.rint((inv @ (q - origin).T).T).astype(int)
        ok = np.all((idx >= 0) & (idx < np.array(sizes)), axis=1)
        return ct[idx[ok, 2], idx[ok, 1], idx[ok, 0]]

    assert np.median(sample(p + 4 * radial)) < -900
    assert np.median(sample(p - 4 * radial)) > -200
    assert -900 < np.median(sample(p)) < -100


# ---- markups ----------------------------------------------------------------------------------

def markups(folder):
    schema = json.load(open(SCHEMA))
    files = sorted(glob.glob(os.path.join(folder, "**", "*.mrk.json"), recursive=True))
    out = {}
    for f in files:
        doc = json.load(open(f))
        jsonschema.validate(doc, schema)
        assert "markups-schema-v1.0.3.json" in doc["@schema"]
        assert len(doc["markups"]) == 1
        m = doc["markups"][0]
        assert m["coordinateSystem"] == "LPS" and m["coordinateUnits"] == "mm"
        assert m["type"] in ("Fiducial", "Curve", "ClosedCurve")
        out[os.path.relpath(f, folder)] = m
    return out


def positions(m):
    return np.array([cp["position"] for cp in m["controlPoints"]], dtype=float)


def test_markups_are_valid_and_where_caps_finds_them(work):
    d = work["dir"]
    mk = markups(str(d / "s"))
    assert "landmarks.mrk.json" in mk and "plan/incision_1.mrk.json" in mk
    assert "plan/wound_border.mrk.json" in mk and mk["plan/wound_border.mrk.json"]["type"] == \
        "ClosedCurve"
    lm = json.loads(run("model", "landmarks", "m", "--no-write", "--json", cwd=d).stdout)["items"]
    pts = {cp["label"]: np.array(cp["position"])
           for cp in mk["landmarks.mrk.json"]["controlPoints"]}
    found = [k for k, v in lm.items() if v["found"]]
    assert len(found) >= 5
    for name in found:
        assert np.linalg.norm(pts[name] - np.array(lm[name]["lps"])) < 0.1, name
    features = json.load(open(d / "m" / "model.json"))["features"]["items"]
    curves = [k for k in mk if k.startswith("features/")]
    assert curves
    for k in curves:
        name = mk[k]["name"]
        assert mk[k]["type"] == "Curve"
        assert np.abs(positions(mk[k]) - np.array(features[name]["lps"])).max() < 0.1, name
    # The plan's points lie on its incision curve; every curve point lies on the skin.
    plan = json.load(open(d / "e.json"))
    cut = positions(mk["plan/incision_1.mrk.json"])
    for pt in plan["points"]:
        assert np.linalg.norm(cut - np.array(pt["lps"]), axis=1).min() < 0.1
    _, skin = poly(d / "s" / "skin.vtk")
    loc = vtkCellLocator()
    loc.SetDataSet(skin)
    loc.BuildLocator()
    for k in ("plan/incision_1.mrk.json", "plan/wound_border.mrk.json"):
        for p in positions(mk[k]):
            closest, cell, sub, dist2 = [0.0, 0.0, 0.0], reference(0), reference(0), \
                reference(0.0)
            loc.FindClosestPoint(p, closest, cell, sub, dist2)
            assert math.sqrt(dist2) < 1.0, (k, p)  # the range image's skin on the isosurface's
    # the oblique model's markups too
    markups(str(d / "so"))


# ---- the post-operative skin ------------------------------------------------------------------

def test_postoperative_skin_carries_caps_tension_and_displacement(work):
    d = work["dir"]
    reader, post = poly(d / "s" / "skin_postop.vtk")
    assert "SPACE=LPS" in reader.GetHeader()
    tension = array(post, "tension_kPa")
    disp = array(post, "displacement_mm").reshape(-1, 3)
    mag = array(post, "displacement_magnitude_mm")
    on = array(post, "on_fe_mesh")
    assert np.allclose(np.linalg.norm(disp, axis=1), mag, atol=1e-4)
    assert np.abs(disp[on == 0]).max() == 0  # the range skin off the finite elements stays
    rendered = json.loads(run("render", "esim", "--model", "m", "-o", "r", "--views", "front",
                              "--image-size", "64", "--tension-map", "--json", "-q",
                              cwd=d).stdout)
    assert tension.max() == pytest.approx(rendered["max_skin_tension_kpa"], rel=1e-5)
    assert tension.max() == pytest.approx(work["s"]["max_tension_kpa"], rel=1e-5)
    # the skin moves no further than the finite-element nodes do (result.vtu, VTK's reader)
    r = vtkXMLUnstructuredGridReader()
    r.SetFileName(str(d / "esim" / "result.vtu"))
    r.Update()
    pd = r.GetOutput().GetPointData()
    u = None
    for i in range(pd.GetNumberOfArrays()):
        a = pd.GetArray(i)
        if "displacement" in pd.GetArrayName(i).lower() and a.GetNumberOfComponents() == 3:
            u = vtk_to_numpy(a)
    assert u is not None
    umax = np.linalg.norm(u, axis=1).max()
    assert 0.3 * umax < mag.max() <= umax + 1e-3


# ---- refusals ---------------------------------------------------------------------------------

def test_bad_input_exits_2_and_writes_nothing(work):
    d = work["dir"]
    cases = [
        (["model", "export-slicer", "m", "--plan", "eo.json", "-o", "bad1"], "another model"),
        (["model", "export-slicer", "m", "-o", "m", "--force"], "input"),
        (["model", "export-slicer", "m", "--result", "nowhere", "-o", "bad2"], "nowhere"),
        (["model", "export-slicer", "nomodel", "-o", "bad3"], "nomodel"),
        (["model", "export-slicer", "m", "-o", "s"], "s"),  # exists, no --force
    ]
    for args, words in cases:
        p = run(*args, cwd=d, check=False)
        assert p.returncode == 2, (args, p.stderr)
        assert words in p.stderr, (args, p.stderr)
    for name in ("bad1", "bad2", "bad3"):
        assert not os.path.exists(d / name)
    assert not [f for f in os.listdir(d) if ".tmp-" in f]
    assert os.path.exists(d / "m" / "model.json")


def test_a_model_whose_volume_is_gone_gives_the_rest_with_a_warning(work):
    d = work["dir"]
    p = run("model", "export-slicer", "mg", "-o", "sg", cwd=d)
    assert "is not there" in p.stderr
    files = os.listdir(d / "sg")
    assert "ct.nrrd" not in files and "tissue.seg.nrrd" not in files
    assert "skin.vtk" in files and "landmarks.mrk.json" in files
    assert json.load(open(d / "sg" / "summary.json"))["warnings"]


def test_a_relative_source_is_found_beside_the_model(work):
    # model.json records the CT as given ("ct.nii.gz", relative to where from-volume ran); run
    # from elsewhere, the export finds it beside the model folder.
    d = work["dir"]
    os.makedirs(d / "elsewhere", exist_ok=True)
    p = run("model", "export-slicer", "../m", "-o", "out", "--json", "-q", cwd=d / "elsewhere")
    assert json.loads(p.stdout)["volume_file"] == "ct.nrrd"
    assert nrrd_header(d / "elsewhere" / "out" / "ct.nrrd") == nrrd_header(d / "s" / "ct.nrrd")
    with open(d / "elsewhere" / "out" / "ct.nrrd", "rb") as a, open(d / "s" / "ct.nrrd", "rb") as b:
        assert a.read().split(b"\n\n", 1)[1] == b.read().split(b"\n\n", 1)[1]  # the voxels
