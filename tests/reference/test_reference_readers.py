"""caps's volume readers against the field's reference readers (docs/formats.md, "Reference
readers").

Every file of the test data that pydicom and nibabel ship (Debian python3-pydicom,
python3-nibabel) is read by `caps volume info FILE --json` and by the reference library. Where
the reference reads a placeable cross-sectional image, caps must read the same geometry (origin,
spacing, direction in LPS, to 1e-4 mm) and the same values after rescale (min, max, mean,
standard deviation, and the centroid of value - min, which moves if a value or an axis does).
Every other file must be refused by caps with exit code 2 and a reason.

A DICOM file named alone is read with its series from its folder (caps's rule): the reference
assembles that series the same way with pydicom (same SeriesInstanceUID, orientation, size and
spacing as the named file; other files at the named file's position left out; sorted along the
normal).

Run by ctest (tests/CMakeLists.txt, CAPS_EXE set); `python3 test_reference_readers.py --table`
prints the verdict table of docs/formats.md.
"""

import concurrent.futures
import functools
import json
import os
import shutil
import subprocess
import sys
import warnings

import numpy as np
import pytest

pydicom = pytest.importorskip("pydicom")
nibabel = pytest.importorskip("nibabel")
try:  # pydicom 2 (Debian 12); pydicom 3 moved it
    from pydicom.pixel_data_handlers.util import apply_modality_lut
except ImportError:  # pragma: no cover
    from pydicom.pixels import apply_modality_lut

warnings.simplefilter("ignore")

PYDICOM_DATA = os.path.join(os.path.dirname(pydicom.__file__), "data", "test_files")
NIBABEL_ROOT = os.path.dirname(nibabel.__file__)
NIBABEL_DATA = [os.path.join(NIBABEL_ROOT, *p)
                for p in (("tests", "data"), ("nicom", "tests", "data"), ("gifti", "tests", "data"))]

# Files the reference cannot decode here (no JPEG-LS decoder for pydicom in Debian) but which are
# lossless encodings of another file of the set: caps's read is compared with that file's.
LOSSLESS_TWINS = {"MR_small_jpeg_ls_lossless.dcm": "MR_small.dcm"}

NIFTI_TYPES = ("Nifti1Image", "Nifti2Image", "Nifti1Pair", "Nifti2Pair")


def data_files():
    out = []
    for root in [PYDICOM_DATA] + NIBABEL_DATA:
        for dirpath, dirnames, filenames in os.walk(root):
            dirnames[:] = sorted(d for d in dirnames if d != "__pycache__")
            out += [os.path.join(dirpath, f) for f in sorted(filenames)]
    return out


def short(path):
    for root, label in [(PYDICOM_DATA, "pydicom"), (NIBABEL_ROOT, "nibabel")]:
        if path.startswith(root + os.sep):
            return label + "/" + os.path.relpath(path, root)
    return path


def caps_exe():
    exe = os.environ.get("CAPS_EXE") or shutil.which("caps")
    if not exe:
        pytest.skip("the caps program is not built (CAPS_EXE)")
    return exe


def run_caps(path, extra=()):
    p = subprocess.run([caps_exe(), "volume", "info", path, "--json", "-q", *extra],
                       capture_output=True, text=True, timeout=120)
    info = json.loads(p.stdout) if p.returncode == 0 else None
    return p.returncode, info, p.stderr.strip()


# ---- reference volumes -----------------------------------------------------------------------

class Reference:
    """A reference read: a float volume indexed [k][j][i] (NaN = no data) and its LPS grid."""

    def __init__(self, data, origin, spacing, direction):
        self.data = np.asarray(data, dtype=np.float64)
        self.origin = np.asarray(origin, dtype=np.float64)
        self.spacing = np.asarray(spacing, dtype=np.float64)
        self.direction = np.asarray(direction, dtype=np.float64)  # columns: i, j, k axes

    def dims(self):
        nk, nj, ni = self.data.shape
        return [ni, nj, nk]

    def moments(self):
        finite = np.isfinite(self.data)
        v = self.data[finite]
        lo = float(v.min())
        k, j, i = np.nonzero(finite)
        ijk = np.stack([i, j, k]).astype(np.float64)
        pos = self.origin[:, None] + self.direction @ (self.spacing[:, None] * ijk)
        w = v - lo
        centroid = (pos @ w) / w.sum() if w.sum() > 0 else self.origin
        return {"min": lo, "max": float(v.max()), "mean": float(v.mean()), "std": float(v.std()),
                "centroid_lps": centroid.tolist(), "outside": int((~finite).sum())}


class Refused(Exception):
    """The reference reads no placeable image from the file (the reason says why)."""


def unit(v):
    v = np.asarray(v, dtype=np.float64)
    return v / np.linalg.norm(v)


def dicom_values(ds, frames):
    arr = ds.pixel_array
    values = apply_modality_lut(arr, ds).astype(np.float32).astype(np.float64)
    return values.reshape(frames, int(ds.Rows), int(ds.Columns))


@functools.lru_cache(maxsize=None)
def dcmread_cached(path):
    """A file of a folder scanned for a series (read once for all the files named in it)."""
    try:
        return pydicom.dcmread(path)
    except Exception:  # noqa: BLE001 - unreadable: left out of the series
        return None


def dicom_image_or_refuse(path):
    try:
        ds = pydicom.dcmread(path)
    except Exception as e:  # noqa: BLE001 - any failure of the reference is a verdict
        raise Refused(f"pydicom cannot read it ({type(e).__name__})")
    if "PixelData" not in ds:
        raise Refused("no pixel data (not an image)")
    if not ds.get("SeriesInstanceUID"):
        raise Refused("no SeriesInstanceUID (type 1): its series cannot be told")
    if int(ds.get("SamplesPerPixel", 1)) != 1 or ds.get("PhotometricInterpretation") != "MONOCHROME2":
        raise Refused(f"not greyscale ({ds.get('PhotometricInterpretation')})")
    if int(ds.get("BitsAllocated", 16)) not in (8, 16, 32):
        raise Refused(f"BitsAllocated {ds.get('BitsAllocated')}")
    for tag in ("ImagePositionPatient", "ImageOrientationPatient", "PixelSpacing"):
        if tag not in ds:
            raise Refused(f"no {tag}: the image cannot be placed")
    return ds


def dicom_reference(path):
    ds = dicom_image_or_refuse(path)
    try:
        frames = int(ds.get("NumberOfFrames", 1) or 1)
    except (TypeError, ValueError):
        raise Refused(f"NumberOfFrames '{ds.get('NumberOfFrames')}' is not a number")
    iop = [float(x) for x in ds.ImageOrientationPatient]
    r, c = unit(iop[:3]), unit(iop[3:])
    c = unit(c - r.dot(c) * r)
    n = np.cross(r, c)
    ps = [float(x) for x in ds.PixelSpacing]
    try:
        values = dicom_values(ds, frames)
    except Exception as e:  # noqa: BLE001
        raise Refused(f"pydicom cannot decode the pixels ({type(e).__name__})")
    if frames > 1:
        offsets = [float(x) for x in ds.get("GridFrameOffsetVector", [])]
        if len(offsets) != frames:
            raise Refused("a multi-frame image without per-frame offsets")
        step = offsets[1] - offsets[0]
        return Reference(values, [float(x) for x in ds.ImagePositionPatient],
                         [ps[1], ps[0], abs(step)],
                         np.column_stack([r, c, n if step > 0 else -n]))
    # One slice named: its series from its folder, assembled as caps does.
    named_d = np.dot([float(x) for x in ds.ImagePositionPatient], n)
    slices = [(named_d, path, ds)]
    folder = os.path.dirname(path)
    for dirpath, dirnames, filenames in os.walk(folder):
        for name in filenames:
            other = os.path.join(dirpath, name)
            if other == path or name == "DICOMDIR" or name.startswith("."):
                continue
            o = dcmread_cached(other)
            try:
                if o is None:
                    continue
                if o.get("SeriesInstanceUID") != ds.SeriesInstanceUID or "PixelData" not in o:
                    continue
                if int(o.get("NumberOfFrames", 1) or 1) != 1:
                    continue
                oiop = [float(x) for x in o.ImageOrientationPatient]
                ops = [float(x) for x in o.PixelSpacing]
                ipp = [float(x) for x in o.ImagePositionPatient]
            except Exception:  # noqa: BLE001 - unreadable or unplaceable: left out
                continue
            if (max(abs(a - b) for a, b in zip(oiop, iop)) >= 1e-3 or o.Rows != ds.Rows
                    or o.Columns != ds.Columns or max(abs(a - b) for a, b in zip(ops, ps)) >= 1e-4):
                continue
            d = float(np.dot(ipp, n))
            if abs(d - named_d) < 0.01:
                continue
            slices.append((d, other, o))
    slices.sort(key=lambda s: s[0])
    gaps = np.diff([s[0] for s in slices])
    if len(gaps) and gaps.min() < 0.01:
        raise Refused("two files of the series lie at one position")
    if len(gaps) and gaps.max() - gaps.min() > max(0.01, 0.01 * float(np.median(gaps))):
        raise Refused(f"uneven slice gaps {gaps.min():.2f}..{gaps.max():.2f} mm (caps resamples or "
                      f"refuses: not compared)")
    stack = []
    for _, f, o in slices:
        try:
            stack.append(dicom_values(o, 1)[0])
        except Exception as e:  # noqa: BLE001
            raise Refused(f"pydicom cannot decode {os.path.basename(f)} ({type(e).__name__})")
    first = [float(x) for x in slices[0][2].ImagePositionPatient]
    dz = (slices[-1][0] - slices[0][0]) / len(gaps) if len(gaps) else 1.0
    return Reference(np.stack(stack), first, [ps[1], ps[0], dz], np.column_stack([r, c, n]))


def nifti_reference(path, volume_index=0):
    try:
        img = nibabel.load(path)
    except Exception as e:  # noqa: BLE001
        raise Refused(f"nibabel cannot read it ({type(e).__name__})")
    kind = type(img).__name__
    if kind not in NIFTI_TYPES:
        raise Refused(f"nibabel reads it as {kind}, a format caps does not read")
    hdr = img.header
    intent = int(hdr["intent_code"])
    if (1004 <= intent <= 1010) or intent >= 2002:
        raise Refused(f"intent {intent} ({hdr.get_intent()[0]}) is not an image")
    try:
        arr = np.asarray(img.dataobj, dtype=np.float64)
    except Exception as e:  # noqa: BLE001
        raise Refused(f"nibabel cannot read the voxels ({type(e).__name__}: {e})")
    shape = arr.shape + (1,) * max(0, 3 - arr.ndim)
    arr = arr.reshape(shape[0], shape[1], shape[2], -1, order="F")[..., volume_index]
    # Values stored as float32 by caps after scaling.
    arr = arr.astype(np.float32).astype(np.float64)
    affine = np.diag([-1.0, -1.0, 1.0]) @ img.affine[:3]
    spacing = np.linalg.norm(affine[:, :3], axis=0)
    return Reference(arr.transpose(2, 1, 0), affine[:, 3], spacing, affine[:, :3] / spacing)


def reference(path, volume_index=0):
    """The reference's read of `path`, or Refused."""
    name = os.path.basename(path)
    if path.startswith(PYDICOM_DATA) or name.endswith(".dcm") or "." not in name:
        if name in LOSSLESS_TWINS:
            return dicom_reference(os.path.join(os.path.dirname(path), LOSSLESS_TWINS[name]))
        return dicom_reference(path)
    return nifti_reference(path, volume_index)


# ---- comparison ------------------------------------------------------------------------------

def differences(info, ref):
    """What differs between caps's JSON and the reference read (empty: they agree)."""
    out = []
    if info["dims"] != ref.dims():
        return [f"dims {info['dims']} != {ref.dims()}"]

    def near(label, a, b, tol):
        a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
        if not np.all(np.abs(a - b) <= tol):
            out.append(f"{label} {a.tolist()} != {b.tolist()}")

    near("origin_lps", info["origin_lps"], ref.origin, 1e-4)
    near("spacing_mm", info["spacing_mm"], ref.spacing, 1e-4)
    near("direction", np.array(info["direction_columns"]).T, ref.direction, 1e-4)
    m = ref.moments()
    scale = max(1.0, abs(m["max"]), abs(m["min"]))
    near("min", info["min"], m["min"], 1e-6 * scale)
    near("max", info["max"], m["max"], 1e-6 * scale)
    near("mean", info["mean"], m["mean"], 1e-6 * scale)
    near("std", info["std"], m["std"], 1e-5 * scale)
    extent = float(np.max(np.abs(ref.origin))) + float(np.sum(ref.spacing * ref.dims()))
    near("centroid_lps", info["centroid_lps"], m["centroid_lps"], 1e-4 + 1e-6 * extent)
    if info["outside_field_voxels"] != m["outside"]:
        out.append(f"outside_field_voxels {info['outside_field_voxels']} != {m['outside']}")
    return out


def verdict(path, extra=(), volume_index=0):
    """(ok, verdict, detail) for one file."""
    rc, info, err = run_caps(path, extra)
    try:
        ref = reference(path, volume_index)
    except Refused as why:
        if rc == 2 and err:
            return True, "refused by both", f"caps: {reason(err)}; reference: {why}"
        if rc == 0 and "not compared" in str(why):
            return True, "read, not compared", f"reference: {why}; caps: {info['notes'][-1]}"
        return False, f"caps exit {rc}", f"reference refuses ({why}); caps: {reason(err) if rc else info}"
    if rc != 0:
        return False, f"caps exit {rc} where the reference reads", reason(err)
    diff = differences(info, ref)
    if diff:
        return False, "values or geometry differ", "; ".join(diff)
    return True, "same values and geometry", f"{info['dims']}, {info['min']:g}..{info['max']:g}"


def reason(err):
    text = err.splitlines()[0] if err else ""
    if text.startswith("caps: error: "):
        text = text[len("caps: error: "):]
    for root in [PYDICOM_DATA] + NIBABEL_DATA:
        text = text.replace(root + os.sep, "")
    return text


FILES = data_files()
# 4-D NIfTI: the last volume too, chosen with --volume-index.
FOURD = [("functional.nii", 19), ("example4d.nii.gz", 1), ("example_nifti2.nii.gz", 1)]


@pytest.fixture(scope="module")
def verdicts():
    jobs = [(f, (), 0) for f in FILES]
    for name, index in FOURD:
        f = os.path.join(NIBABEL_DATA[0], name)
        if os.path.exists(f):
            jobs.append((f, ("--volume-index", str(index)), index))
    with concurrent.futures.ThreadPoolExecutor(max_workers=4) as pool:
        results = pool.map(lambda j: verdict(*j), jobs)
        return {(j[0], j[2]): r for j, r in zip(jobs, results)}


def test_the_reference_data_are_installed():
    assert os.path.isfile(os.path.join(PYDICOM_DATA, "MR_small.dcm"))
    assert os.path.isfile(os.path.join(NIBABEL_DATA[0], "functional.nii"))


@pytest.mark.parametrize("path", FILES, ids=short)
def test_caps_agrees_with_the_reference(verdicts, path):
    ok, what, detail = verdicts[(path, 0)]
    assert ok, f"{short(path)}: {what}: {detail}"


@pytest.mark.parametrize("name,index", FOURD)
def test_a_chosen_volume_of_a_4d_nifti_agrees(verdicts, name, index):
    path = os.path.join(NIBABEL_DATA[0], name)
    ok, what, detail = verdicts[(path, index)]
    assert ok, f"{name} volume {index}: {what}: {detail}"


def test_the_big_endian_mr_reads_as_the_little_endian_one():
    folder = PYDICOM_DATA
    _, little, _ = run_caps(os.path.join(folder, "MR_small.dcm"))
    for name in ("MR_small_bigendian.dcm", "MR_small_expb.dcm"):
        rc, big, err = run_caps(os.path.join(folder, name))
        assert rc == 0, err
        for key in ("min", "max", "mean", "std", "centroid_lps", "origin_lps"):
            assert big[key] == pytest.approx(little[key], rel=1e-9, abs=1e-9), (name, key)


def test_one_file_reads_its_series_beside_a_damaged_file_of_another():
    rc, info, err = run_caps(os.path.join(PYDICOM_DATA, "CT_small.dcm"))
    assert rc == 0, err
    assert info["dims"] == [128, 128, 1]
    assert any("MR_truncated.dcm" in n for n in info["notes"]), info["notes"]


# What it would take for caps to read a file the reference reads (docs/formats.md).
WOULD_TAKE = [
    (".dconn.nii", "refused by design: CIFTI is a matrix over brain-ordinates, not an image"),
    (".mnc", "MINC 1 (NetCDF) / MINC 2 (HDF5): a reader over libminc2 or netCDF/HDF5"),
    (".mgz", "FreeSurfer MGH/MGZ: a small own parser (gzip, a 284-byte header, vox2ras)"),
    (".HEAD", "AFNI HEAD/BRIK: a parser of the HEAD attributes and the BRIK data"),
    (".BRIK", "AFNI HEAD/BRIK: a parser of the HEAD attributes and the BRIK data"),
    (".BRIK.gz", "AFNI HEAD/BRIK: a parser of the HEAD attributes and the BRIK data"),
    (".PAR", "Philips PAR/REC: a parser of PAR and its slice orientation conventions"),
    (".REC", "Philips PAR/REC: a parser of PAR and its slice orientation conventions"),
    (".gii", "out of scope: GIFTI holds surfaces and per-vertex data, not volumes"),
    (".gii.gz", "out of scope: GIFTI holds surfaces and per-vertex data, not volumes"),
    (".gii.bz2", "out of scope: GIFTI holds surfaces and per-vertex data, not volumes"),
    ("analyze.hdr", "Analyze 7.5 has no orientation (left/right unknown); its .img is not "
                    "shipped either"),
]


def would_take(path):
    for ending, what in WOULD_TAKE:
        if path.endswith(ending):
            return what
    return "a reader for the format"


def table():
    """Markdown rows: file(s), verdict, caps's reason or read, the reference's."""
    rows = ["| File | Verdict | caps | Reference |", "|---|---|---|---|"]
    groups = []
    for f in FILES:
        ok, what, detail = verdict(f)
        caps_part, _, ref_part = detail.partition("; reference: ")
        caps_part = caps_part.removeprefix("caps: ")
        first, _, rest = caps_part.partition(": ")
        if rest and " " not in first:  # the file or folder named first
            caps_part = rest
        caps_part = caps_part.split("; ")[0]
        if not ok:
            what = "FAIL: " + what
        elif ref_part.startswith("nibabel reads it as") or (
                what == "refused by both" and "nibabel reads" in ref_part):
            what = "reference reads, caps refuses: " + would_take(f)
        elif what == "same values and geometry":
            ref_part = "reads the same"
        key = (os.path.dirname(f), what, caps_part, ref_part)
        if groups and groups[-1][0] == key and what == "refused by both":
            groups[-1][1].append(f)
        else:
            groups.append((key, [f]))
    for (_, what, caps_part, ref_part), files in groups:
        label = short(files[0]) if len(files) == 1 else (
            f"{short(files[0])} .. {os.path.basename(files[-1])} ({len(files)} files)")
        cell = lambda t: t.replace("|", "/")  # noqa: E731
        rows.append(f"| {cell(label)} | {cell(what)} | {cell(caps_part)} | {cell(ref_part)} |")
    return "\n".join(rows)


if __name__ == "__main__" and "--table" in sys.argv:
    print(table())
