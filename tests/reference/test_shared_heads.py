"""The project's own heads (../shared/data and Debian's mricron-data) read by caps and by the
field's reference readers, compared as test_reference_readers.py compares the readers' test
data: the same grid (dims, origin, spacing, direction in LPS) and the same values (min, max, mean,
standard deviation, and the centroid of value - min, which moves if a value or an axis does).

* VTK's headsq (`ct/vtk-headsq/quarter.nhdr`, 93 detached raw slices named by a `data file:`
  pattern): the NRRD format's own definition (the samples in file order, the first axis fastest,
  each `quarter.N` one slice of 64 x 64 little-endian shorts), decoded here with numpy; and VTK's
  NRRD reader (vtkNrrdReader, Debian python3-vtk9), independent of teem, which caps reads NRRD
  with. VTK's image readers put the file's first row at the top of the image (vtkImageReader2's
  FileLowerLeft off, which vtkNrrdReader keeps): its rows are the file's reversed, so VTK's read
  is compared with its rows put back in file order. The header has no space directions: caps
  takes the file's axes as they are, at the origin, and says that the true orientation is
  unknown.
* ch2 (`ch2.nii.gz`, a T1 MR): nibabel.

Skipped where a file or a reference library is missing (the CT from ../shared, the MR from
Debian's mricron-data; scripts/setup.sh installs both libraries). Run by ctest's
reference_readers (tests/CMakeLists.txt).
"""

import os

import numpy as np
import pytest

from test_reference_readers import Reference, differences, nifti_reference, run_caps

HERE = os.path.dirname(os.path.abspath(__file__))
SHARED = os.environ.get("CAPS_SHARED_DATA") or os.path.join(HERE, "..", "..", "..", "shared", "data")
HEADSQ = os.path.join(SHARED, "ct", "vtk-headsq", "quarter.nhdr")
CH2 = "/usr/share/mricron/templates/ch2.nii.gz"


def vtk_nrrd_reference(path):
    image_io = pytest.importorskip("vtkmodules.vtkIOImage")
    numpy_support = pytest.importorskip("vtkmodules.util.numpy_support")
    reader = image_io.vtkNrrdReader()
    reader.SetFileName(path)
    reader.Update()
    assert reader.GetFileLowerLeft() == 0  # VTK's top-down rows, undone below
    image = reader.GetOutput()
    ni, nj, nk = image.GetDimensions()
    scalars = image.GetPointData().GetScalars()
    assert scalars is not None, f"VTK read no voxels from {path}"
    values = numpy_support.vtk_to_numpy(scalars).astype(np.float64).reshape(nk, nj, ni)
    return Reference(values[:, ::-1, :], image.GetOrigin(), image.GetSpacing(), np.eye(3))


def headsq_by_its_definition():
    """quarter.1 .. quarter.93 (`data file: quarter.%d 1 93 1`), 64 x 64 little-endian int16."""
    folder = os.path.dirname(HEADSQ)
    slices = [np.fromfile(os.path.join(folder, f"quarter.{n}"), dtype="<i2") for n in range(1, 94)]
    assert all(s.size == 64 * 64 for s in slices)
    values = np.stack([s.reshape(64, 64) for s in slices]).astype(np.float64)
    return Reference(values, [0, 0, 0], [3.2, 3.2, 1.5], np.eye(3))


@pytest.fixture(scope="module")
def headsq():
    if not os.path.isfile(HEADSQ):
        pytest.skip(f"{HEADSQ} is missing")
    rc, info, err = run_caps(HEADSQ)
    assert rc == 0, err
    return info


def test_headsq_reads_as_the_nrrd_format_defines_it(headsq):
    assert differences(headsq, headsq_by_its_definition()) == []
    assert any("orientation is unknown" in n for n in headsq["notes"]), headsq["notes"]


def test_headsq_reads_as_vtks_own_nrrd_reader_reads_it(headsq):
    ref = vtk_nrrd_reference(HEADSQ)
    assert ref.dims() == [64, 64, 93]
    assert differences(headsq, ref) == []
    # Without undoing VTK's row order the centroid differs (it is what the comparison sees).
    flipped = Reference(ref.data[:, ::-1, :], ref.origin, ref.spacing, ref.direction)
    assert any(d.startswith("centroid_lps") for d in differences(headsq, flipped))


def test_ch2_reads_as_nibabel_reads_it():
    pytest.importorskip("nibabel")
    if not os.path.isfile(CH2):
        pytest.skip(f"{CH2} is missing (apt-get install mricron-data)")
    rc, info, err = run_caps(CH2)
    assert rc == 0, err
    assert differences(info, nifti_reference(CH2)) == []


GE_TILT = os.path.join(SHARED, "ct", "ge-head-tilt")


def test_the_tilted_ge_series_is_resampled_in_its_place():
    """The GE head (28 slices, 18.5 deg gantry tilt, 4 then 7 mm apart) is resampled by caps onto
    a regular grid on the slices' rows, columns and normal; pydicom reads each slice where its
    header puts it. The grid's axes must be the slices', and the centroid of
    value - min over the head (each slice weighted by the half gaps on either side of it, as the
    linear interpolation between slices weights it) the same within 0.5 mm: a tilt applied the
    wrong way round shears the head by tan(18.5 deg) of each slice's distance from the centre,
    slices taken in the wrong order move it along the axis."""
    pydicom = pytest.importorskip("pydicom")
    from test_reference_readers import apply_modality_lut
    files = sorted(f for f in os.listdir(GE_TILT) if f.endswith(".dcm")) if os.path.isdir(GE_TILT) else []
    if not files:
        pytest.skip(f"{GE_TILT} is missing")
    rc, info, err = run_caps(os.path.join(GE_TILT, files[0]))
    assert rc == 0, err
    assert any("gantry tilt 18.5 deg" in n for n in info["notes"]), info["notes"]
    slices = []
    for f in files:
        ds = pydicom.dcmread(os.path.join(GE_TILT, f))
        iop = np.array([float(x) for x in ds.ImageOrientationPatient])
        ipp = np.array([float(x) for x in ds.ImagePositionPatient])
        n = np.cross(iop[:3], iop[3:])
        values = apply_modality_lut(ds.pixel_array, ds).astype(np.float64)
        slices.append((float(ipp @ n), ipp, iop[:3], iop[3:], [float(x) for x in ds.PixelSpacing],
                       values))
    slices.sort(key=lambda s: s[0])
    origins = np.array([s[1] for s in slices])
    # The slices' rows, columns and normal are the grid's axes; the slices' origins stack along
    # the scanner's axis, 18.5 deg off the normal: the shear is what the resampling takes out.
    r, c = slices[0][2], slices[0][3]
    axes = np.array(info["direction_columns"])
    for got, want in zip(axes, (r, c, np.cross(r, c))):
        assert np.abs(got - want).max() < 1e-4, (axes, r, c)
    stacking = (origins[-1] - origins[0]) / np.linalg.norm(origins[-1] - origins[0])
    assert np.degrees(np.arccos(stacking @ np.cross(r, c))) == pytest.approx(18.5, abs=0.05)
    lo = min(s[5].min() for s in slices)
    assert info["min"] == pytest.approx(lo)
    gaps = np.linalg.norm(np.diff(origins, axis=0), axis=1)
    weight = np.zeros(len(slices))
    weight[:-1] += gaps / 2
    weight[1:] += gaps / 2
    total, moment = 0.0, np.zeros(3)
    for (_, ipp, r, c, ps, v), wk in zip(slices, weight):
        rows, cols = np.mgrid[0:v.shape[0], 0:v.shape[1]]
        w = (v - lo) * wk
        moment += ipp * w.sum() + r * ps[1] * (cols * w).sum() + c * ps[0] * (rows * w).sum()
        total += w.sum()
    centroid = moment / total
    assert np.abs(np.array(info["centroid_lps"]) - centroid).max() < 0.5, (info["centroid_lps"], centroid)
