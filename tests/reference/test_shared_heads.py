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
