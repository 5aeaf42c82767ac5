"""The phantom patient model the tests share (96 x 96 x 90 voxels of 2.5 mm, a 128 x 64
cylindrical grid, as tests/phantom_model.hpp), built through Python as a user would."""

import os
import shutil
import subprocess

import pytest

import caps


@pytest.fixture(scope="session")
def work(tmp_path_factory):
    return tmp_path_factory.mktemp("caps_python")


@pytest.fixture(scope="session")
def model(work):
    ct = work / "ct.nii.gz"
    caps.phantom(ct, voxels="96,96,90", spacing="2.5,2.5,2.5")
    out = work / "model"
    caps.model_from_volume(ct, out, n_theta=128, n_z=64)
    return out


@pytest.fixture(scope="session")
def cli():
    """Runs the caps program (CAPS_EXE, set by ctest; else caps on the PATH)."""
    exe = os.environ.get("CAPS_EXE") or shutil.which("caps")
    if not exe:
        pytest.skip("no caps program: set CAPS_EXE")

    def run(*args):
        return subprocess.run([exe, *map(str, args)], capture_output=True, text=True)

    return run
