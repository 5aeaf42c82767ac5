// Hostile inputs: a catalogue of files built here that once crashed caps, made it allocate
// gigabytes, read wrong data silently or destroy an input. Each is run through the caps program
// as a user would: exit code 2, a message with the key words, no output left behind and the input
// unchanged (docs/reliability.md lists the limits these cases check).
#include <gtest/gtest.h>

#include "cli_outcome.hpp"
#include <nlohmann/json.hpp>
#include <signal.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <sstream>
#include <string>
#include <tuple>
#include <vector>

namespace fs = std::filesystem;

namespace {

using caps_test::Outcome;
using caps_test::slurp;
using caps_test::write_file;

// A whole folder's files and contents, to check that an input was left unchanged.
std::string snapshot(const fs::path& p) {
  if (!fs::is_directory(p)) return fs::exists(p) ? slurp(p) : std::string("<missing>");
  std::vector<fs::path> files;
  for (const auto& e : fs::recursive_directory_iterator(p))
    if (e.is_regular_file()) files.push_back(e.path());
  std::sort(files.begin(), files.end());
  std::string s;
  for (const auto& f : files) s += f.string() + "\n" + slurp(f) + "\n";
  return s;
}

// gzip-compressed bytes, through the gzip program (the test programs of the CLI link no zlib).
std::string gzip(const std::string& data) {
  const fs::path raw = fs::temp_directory_path() / ("caps_hostile_gz_" + std::to_string(::getpid()));
  write_file(raw, data);
  const int rc = std::system(("gzip -9 -f -k -n " + raw.string()).c_str());
  EXPECT_EQ(rc, 0);
  const fs::path gz = raw.string() + ".gz";
  std::string out = slurp(gz);
  fs::remove(raw);
  fs::remove(gz);
  return out;
}

std::string nested(const std::string& key, int depth) {
  return "{\"format\": \"caps-plan\", \"" + key + "\": " + std::string(depth, '[') +
         std::string(depth, ']') + "}";
}

class Hostile : public caps_test::CliTest {
 protected:
  static void SetUpTestSuite() { dir = caps_test::fresh_temp_dir("caps_hostile_"); }
  // Expects a refusal of `args`: exit code 2, every key word in the message, `output` not created,
  // no temporary left beside it, and `input` (a file or folder) unchanged.
  static void expect_refused(const std::string& args, const std::vector<std::string>& words,
                             const fs::path& output, const fs::path& input) {
    const std::string before = snapshot(input);
    const Outcome r = run(args);
    EXPECT_EQ(r.code, 2) << args << "\n" << r.err;
    for (const auto& w : words)
      EXPECT_NE(r.err.find(w), std::string::npos) << args << "\nmessage lacks '" << w << "':\n" << r.err;
    EXPECT_EQ(r.err.find("internal error"), std::string::npos) << r.err;
    if (!output.empty()) {
      EXPECT_FALSE(fs::exists(output) && !fs::exists(input)) << output;
      for (const auto& e : fs::directory_iterator(output.parent_path()))
        EXPECT_EQ(e.path().filename().string().find(".tmp-"), std::string::npos)
            << "temporary left behind: " << e.path();
    }
    EXPECT_EQ(snapshot(input), before) << args << ": the input changed";
  }
  // The same for a command whose output must not exist afterwards.
  static void expect_refused_new(const std::string& args, const std::vector<std::string>& words,
                                 const fs::path& output, const fs::path& input) {
    fs::remove_all(output);
    expect_refused(args, words, output, input);
    EXPECT_FALSE(fs::exists(output)) << output;
  }
};

// ---- crashes

TEST_F(Hostile, MetaImagePatternIsNeverAFormatString) {
  const fs::path out = dir / "mha_out";
  for (const std::string pattern : {"slice%n%n%n%n.raw", "slice%s%s%s.raw", "slice%d%d.raw",
                                    "slice%999999999d.raw", "slice%x.raw"}) {
    const fs::path mhd = dir / "pattern.mhd";
    write_file(mhd, "ObjectType = Image\nNDims = 3\nDimSize = 4 4 3\nElementType = MET_SHORT\n"
                    "ElementSpacing = 1 1 1\nElementDataFile = " + pattern + " 1 3 1\n");
    expect_refused_new("volume info " + mhd.string(), {"pattern.mhd", "ElementDataFile", "%d"},
                       out, mhd);
  }
  // The ITK form still works: slice001.raw .. slice003.raw.
  for (int i = 1; i <= 3; ++i) write_file(dir / ("slice00" + std::to_string(i) + ".raw"), std::string(32, '\0'));
  write_file(dir / "good.mhd", "ObjectType = Image\nNDims = 3\nDimSize = 4 4 3\nElementType = "
                               "MET_SHORT\nElementSpacing = 1 1 1\nElementDataFile = slice%03d.raw 1 3 1\n");
  const Outcome r = run("volume info " + (dir / "good.mhd").string());
  EXPECT_EQ(r.code, 0) << r.err;
}

TEST_F(Hostile, JsonNestedTooDeepIsRefusedNotACrash) {
  const int deep = 200000;
  // A plan.
  const fs::path plan = dir / "deep_plan.json";
  write_file(plan, nested("sutures", deep));
  expect_refused_new("plan check " + plan.string(), {"deep_plan.json", "nested"}, dir / "none", plan);
  expect_refused_new("plan show " + plan.string() + " -o " + (dir / "deep.png").string(),
                     {"deep_plan.json", "nested"}, dir / "deep.png", plan);
  // A model.json.
  const fs::path model = dir / "deep_model";
  fs::create_directories(model);
  write_file(model / "model.json", "{\"format_version\": 1, \"axis\": " + std::string(deep, '[') +
                                       std::string(deep, ']') + "}");
  expect_refused_new("model info " + model.string(), {"model.json", "nested"}, dir / "none", model);
  // A mesh.json.
  const fs::path mesh = dir / "deep_mesh";
  fs::create_directories(mesh);
  write_file(mesh / "mesh.json", "{\"format\": \"caps-mesh\", \"loads_n\": " +
                                     std::string(deep, '[') + std::string(deep, ']') + "}");
  write_file(mesh / "mesh.vtu", "<VTKFile/>");
  expect_refused_new("solve " + mesh.string() + " -o " + (dir / "deep_result").string(),
                     {"mesh.json", "nested"}, dir / "deep_result", mesh);
  // A procedure file.
  const fs::path proc = dir / "deep_proc.json";
  write_file(proc, "{\"format\": \"caps-procedure\", \"x\": " + std::string(deep, '{') + "}");
  expect_refused_new("plan new " + proc.string() + " --model " + model.string() + " --at 0,60 -o " +
                         (dir / "p.json").string(),
                     {"deep_proc.json", "nested"}, dir / "p.json", proc);
  // A glTF scan.
  const fs::path gltf = dir / "deep.gltf";
  write_file(gltf, "{\"asset\": {\"version\": \"2.0\"}, \"extras\": " + std::string(deep, '[') +
                       std::string(deep, ']') + "}");
  expect_refused_new("model from-scan " + gltf.string() + " --thickness 6 -o " + (dir / "s").string(),
                     {"deep.gltf", "nested"}, dir / "s", gltf);
  // Brackets inside strings do not count.
  const fs::path text = dir / "brackets_plan.json";
  write_file(text, "{\"format\": \"caps-plan\", \"notes\": [\"" + std::string(1000, '[') + "\\\"\"]}");
  const Outcome r = run("plan check " + text.string());
  EXPECT_EQ(r.err.find("nested"), std::string::npos) << r.err;
}

// A minimal glTF with one triangle in a data: URI; `accessor` and `nodes` replace the parts
// under test.
std::string gltf_with(const std::string& count, const std::string& nodes) {
  // 3 vertices x 3 floats = 36 bytes of zeros, base64.
  const std::string b64(48, 'A');
  return "{\"asset\": {\"version\": \"2.0\"}, \"scene\": 0, \"scenes\": [{\"nodes\": [0]}],"
         " \"nodes\": " + nodes + ", \"meshes\": [{\"primitives\": [{\"attributes\": "
         "{\"POSITION\": 0}}]}], \"accessors\": [{\"bufferView\": 0, \"componentType\": 5126, "
         "\"count\": " + count + ", \"type\": \"VEC3\"}], \"bufferViews\": [{\"buffer\": 0, "
         "\"byteLength\": 36}], \"buffers\": [{\"byteLength\": 36, \"uri\": "
         "\"data:application/octet-stream;base64," + b64 + "\"}]}";
}

TEST_F(Hostile, GltfCountsNearTwoToTheSixtyTwoAreRefused) {
  const fs::path out = dir / "gltf_out";
  for (const std::string count : {"4611686018427387904", "4611686018427387905", "18446744073709551615",
                                  "1000"}) {
    const fs::path gltf = dir / "huge_count.gltf";
    write_file(gltf, gltf_with(count, "[{\"mesh\": 0}]"));
    expect_refused_new("model from-scan " + gltf.string() + " --thickness 6 -o " + out.string(),
                       {"huge_count.gltf"}, out, gltf);
  }
}

TEST_F(Hostile, GltfNodeThatIsItsOwnChildIsRefused) {
  const fs::path out = dir / "gltf_cycle_out";
  const fs::path gltf = dir / "cycle.gltf";
  write_file(gltf, gltf_with("3", "[{\"mesh\": 0, \"children\": [0]}]"));
  expect_refused_new("model from-scan " + gltf.string() + " --thickness 6 -o " + out.string(),
                     {"cycle.gltf", "node 0", "cycle"}, out, gltf);
  write_file(gltf, gltf_with("3", "[{\"mesh\": 0, \"children\": [1]}, {\"children\": [0]}]"));
  expect_refused_new("model from-scan " + gltf.string() + " --thickness 6 -o " + out.string(),
                     {"cycle.gltf", "cycle"}, out, gltf);
}

TEST_F(Hostile, GltfPositionsWithTooFewComponentsAreRefused) {
  // A POSITION accessor of type VEC2: reading three components ran past each element (ASan
  // found a heap overflow with fuzz/fuzz_gltf.cpp).
  const fs::path out = dir / "gltf_vec2_out";
  const fs::path gltf = dir / "vec2.gltf";
  std::string text = gltf_with("3", "[{\"mesh\": 0}]");
  text.replace(text.find("\"VEC3\""), 6, "\"VEC2\"");
  write_file(gltf, text);
  expect_refused_new("model from-scan " + gltf.string() + " --thickness 6 -o " + out.string(),
                     {"vec2.gltf", "POSITION", "VEC3"}, out, gltf);
}

TEST_F(Hostile, GltfIndicesOutOfRangeAreRefused) {
  // One triangle whose indices (uint16) are 0, 1, 7: there are 3 vertices.
  const fs::path out = dir / "gltf_index_out";
  const fs::path gltf = dir / "bad_index.gltf";
  write_file(gltf,
             "{\"asset\": {\"version\": \"2.0\"}, \"scene\": 0, \"scenes\": [{\"nodes\": [0]}], "
             "\"nodes\": [{\"mesh\": 0}], \"meshes\": [{\"primitives\": [{\"attributes\": "
             "{\"POSITION\": 0}, \"indices\": 1}]}], \"accessors\": [{\"bufferView\": 0, "
             "\"componentType\": 5126, \"count\": 3, \"type\": \"VEC3\"}, {\"bufferView\": 1, "
             "\"componentType\": 5123, \"count\": 3, \"type\": \"SCALAR\"}], \"bufferViews\": "
             "[{\"buffer\": 0, \"byteLength\": 36}, {\"buffer\": 0, \"byteOffset\": 36, "
             "\"byteLength\": 6}], \"buffers\": [{\"byteLength\": 42, \"uri\": "
             "\"data:application/octet-stream;base64,"
             "AAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAABAAcA\"}]}");
  expect_refused_new("model from-scan " + gltf.string() + " --thickness 6 -o " + out.string(),
                     {"bad_index.gltf", "index 2", "7"}, out, gltf);
}

TEST_F(Hostile, DicomFolderWithAStrayTextFileIsReadWithAWarning) {
  const fs::path ge = fs::path(CAPS_SHARED_DATA) / "ct" / "ge-head-tilt";
  if (!fs::exists(ge)) GTEST_SKIP() << "no shared DICOM data";
  const fs::path folder = dir / "dicom_stray";
  fs::create_directories(folder);
  for (const auto& e : fs::directory_iterator(ge))
    if (e.path().extension() == ".dcm") fs::copy_file(e.path(), folder / e.path().filename());
  for (const std::string name : {"README", "notes.txt", "x.dcm"})
    write_file(folder / name, "exported by a workstation\n");
  write_file(folder / "empty", "");
  const Outcome r = run("volume info " + folder.string());
  EXPECT_EQ(r.code, 0) << r.err;
  EXPECT_NE((r.out + r.err).find("skipped 4 non-DICOM file"), std::string::npos) << r.out << r.err;
  // One slice given on its own reads its series from the folder, and lists the folder's series
  // (it used to fail with "not a folder").
  const Outcome one = run("volume info " + (folder / "01.dcm").string() + " --json");
  EXPECT_EQ(one.code, 0) << one.err;
  EXPECT_NE(one.out.find("\"series\""), std::string::npos) << one.out;
  EXPECT_NE(one.out.find("\"files\": 28"), std::string::npos) << one.out;
  // The stray file given on its own is refused.
  expect_refused_new("volume info " + (folder / "x.dcm").string(), {"x.dcm", "not a DICOM"},
                     dir / "none", folder / "x.dcm");
}

// ---- unbounded allocations from tiny files

// A NIfTI-1 header (348 bytes + 4 extension bytes) declaring `nx x ny x nz` voxels of `datatype`
// (`bitpix` bits) with the given pixdim, followed by `data`.
std::string nifti(int nx, int ny, int nz, short datatype, short bitpix, float pixdim,
                  const std::string& data = "") {
  std::string h(352, '\0');
  auto put = [&](std::size_t at, const auto& v) { std::memcpy(&h[at], &v, sizeof v); };
  put(0, std::int32_t{348});
  const std::int16_t dim[8] = {3, static_cast<std::int16_t>(nx), static_cast<std::int16_t>(ny),
                               static_cast<std::int16_t>(nz), 1, 1, 1, 1};
  std::memcpy(&h[40], dim, sizeof dim);
  put(70, datatype);
  put(72, bitpix);
  const float pixd[8] = {1, pixdim, pixdim, pixdim, 1, 1, 1, 1};
  std::memcpy(&h[76], pixd, sizeof pixd);
  put(108, 352.0f);  // vox_offset
  put(112, 1.0f);    // scl_slope
  std::memcpy(&h[344], "n+1", 4);
  return h + data;
}

TEST_F(Hostile, TinyVolumeFilesDeclaringGigabytesAreRefusedBeforeAllocating) {
  const fs::path out = dir / "budget_out";
  // 2048 x 2048 x 512 doubles: 2^31 voxels, 24 GiB with the float volume; a 70-byte .nii.gz.
  const fs::path nii = dir / "huge.nii.gz";
  write_file(nii, gzip(nifti(2048, 2048, 512, 64, 64, 1.0f)));
  EXPECT_LT(fs::file_size(nii), 200u);
  expect_refused_new("model from-volume " + nii.string() + " -o " + out.string(),
                     {"huge.nii.gz", "max_bytes"}, out, nii);
  // The budget is an option: a small volume refused under a smaller limit.
  const fs::path small = dir / "small.nii";
  write_file(small, nifti(20, 20, 20, 4, 16, 1.0f, std::string(20 * 20 * 20 * 2, '\0')));
  expect_refused_new("volume info " + small.string() + " --max-voxels 1000",
                     {"small.nii", "8000", "max_voxels"}, out, small);
  EXPECT_EQ(run("volume info " + small.string() + " --max-voxels 8000").code, 0);
  // Gzip NRRD and zlib MetaImage headers declaring the same.
  const fs::path nrrd = dir / "huge.nrrd";
  write_file(nrrd, "NRRD0004\ntype: double\ndimension: 3\nsizes: 2048 2048 512\nspacings: 1 1 1\n"
                   "encoding: gzip\nendian: little\n\n" + gzip(std::string(64, '\0')));
  expect_refused_new("volume info " + nrrd.string(), {"huge.nrrd", "max_bytes"}, out, nrrd);
  const fs::path mha = dir / "huge.mha";
  write_file(mha, "ObjectType = Image\nNDims = 3\nDimSize = 2048 2048 512\nElementType = MET_DOUBLE\n"
                  "CompressedData = True\nElementDataFile = LOCAL\n" + gzip(std::string(64, '\0')));
  expect_refused_new("volume info " + mha.string(), {"huge.mha", "max_bytes"}, out, mha);
  // CompressedDataSize and HeaderSize of 1e30.
  write_file(mha, "ObjectType = Image\nNDims = 3\nDimSize = 4 4 4\nElementType = MET_SHORT\n"
                  "CompressedData = True\nCompressedDataSize = 1e30\nElementDataFile = LOCAL\n" +
                      gzip(std::string(128, '\0')));
  expect_refused_new("volume info " + mha.string(), {"huge.mha", "CompressedDataSize"}, out, mha);
  // A limit that is not a positive number.
  expect_refused_new("volume info " + small.string() + " --max-bytes -5", {"max_bytes"}, out, small);
}

TEST_F(Hostile, MeshCountsBeyondTheFileAreRefusedBeforeAllocating) {
  const fs::path out = dir / "mesh_count_out";
  const fs::path ply = dir / "liar.ply";
  write_file(ply, "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
                  "property float z\nelement face 1\nproperty list uint int vertex_indices\n"
                  "end_header\n0 0 0\n1 0 0\n0 1 0\n2000000000 0 1 2\n");
  expect_refused_new("model from-scan " + ply.string() + " --thickness 6 -o " + out.string(),
                     {"liar.ply", "2e+09"}, out, ply);
  const fs::path vtk = dir / "liar.vtk";
  const std::string head = "# vtk DataFile Version 3.0\nliar\nASCII\nDATASET POLYDATA\n";
  write_file(vtk, head + "POINTS 3 float\n0 0 0 1 0 0 0 1 0\nPOLYGONS 1 4\n2000000000 0 1 2\n");
  expect_refused_new("model from-scan " + vtk.string() + " --thickness 6 -o " + out.string(),
                     {"liar.vtk", "POLYGONS"}, out, vtk);
  write_file(vtk, head + "POINTS 2000000000 float\n0 0 0\n");
  expect_refused_new("model from-scan " + vtk.string() + " --thickness 6 -o " + out.string(),
                     {"liar.vtk", "POINTS"}, out, vtk);
}

TEST_F(Hostile, DicomRowsAndColumnsBeyondTheBudgetAreRefusedBeforeDecoding) {
  const fs::path ge = fs::path(CAPS_SHARED_DATA) / "ct" / "ge-head-tilt" / "01.dcm";
  if (!fs::exists(ge)) GTEST_SKIP() << "no shared DICOM data";
  std::string bytes = slurp(ge);
  // Rows (0028,0010) and Columns (0028,0011), explicit VR US, set to 65535.
  for (const char element : {'\x10', '\x11'}) {
    const std::string tag = std::string("\x28\x00", 2) + element + std::string("\x00US\x02\x00", 5);
    const auto at = bytes.find(tag);
    ASSERT_NE(at, std::string::npos);
    bytes[at + 8] = '\xff';
    bytes[at + 9] = '\xff';
  }
  const fs::path folder = dir / "dicom_huge";
  fs::create_directories(folder);
  write_file(folder / "01.dcm", bytes);
  expect_refused_new("volume info " + folder.string(), {"01.dcm", "65535x65535"}, dir / "none",
                     folder);
}

// ---- bad data accepted silently

TEST_F(Hostile, NonFiniteSpacingAndVoxelsAreRefused) {
  const fs::path out = dir / "nan_out";
  const fs::path nan_pixdim = dir / "nan_pixdim.nii";
  write_file(nan_pixdim, nifti(4, 4, 4, 4, 16, std::nanf(""), std::string(128, '\0')));
  expect_refused_new("volume info " + nan_pixdim.string(), {"nan_pixdim.nii", "pixdim"}, out,
                     nan_pixdim);
  const fs::path inf_pixdim = dir / "inf_pixdim.nii";
  write_file(inf_pixdim, nifti(4, 4, 4, 4, 16, INFINITY, std::string(128, '\0')));
  expect_refused_new("volume info " + inf_pixdim.string(), {"inf_pixdim.nii", "pixdim"}, out,
                     inf_pixdim);
  std::string floats(64 * 4, '\0');
  const float nan = std::nanf("");
  std::memcpy(&floats[4 * 21], &nan, 4);  // voxel (1, 1, 1)
  const fs::path nan_voxel = dir / "nan_voxel.nii";
  write_file(nan_voxel, nifti(4, 4, 4, 16, 32, 1.0f, floats));
  expect_refused_new("volume info " + nan_voxel.string(), {"nan_voxel.nii", "(1, 1, 1)", "finite"},
                     out, nan_voxel);
}

TEST_F(Hostile, NiftiOrientationThatIsNotANumberIsRefused) {
  // sform_code 0 and a qform whose quaternion or offset is NaN or infinite: nifti2_io replaces
  // them with 0 and the volume was read "with the orientation from the qform", one it invented.
  const std::string voxels(128, '\0');
  auto with_qform = [&](int field, float value) {
    std::string h = nifti(4, 4, 4, 4, 16, 1.0f, voxels);
    const std::int16_t qform_code = 1;
    std::memcpy(&h[252], &qform_code, 2);
    std::memcpy(&h[256 + 4 * field], &value, 4);  // quatern_b, c, d, qoffset_x, y, z
    return h;
  };
  const fs::path nii = dir / "bad_qform.nii";
  for (const auto& [field, value, word] : std::vector<std::tuple<int, float, std::string>>{
           {0, std::nanf(""), "quatern_b"}, {2, INFINITY, "quatern_d"},
           {3, -INFINITY, "qoffset_x"}, {5, std::nanf(""), "qoffset_z"}}) {
    write_file(nii, with_qform(field, value));
    expect_refused_new("volume info " + nii.string(), {"bad_qform.nii", word, "qform"},
                       dir / "none", nii);
  }
  // The same qform with numbers is read from the qform.
  write_file(nii, with_qform(3, 10.0f));
  const Outcome ok = run("volume info " + nii.string());
  EXPECT_EQ(ok.code, 0) << ok.err;
  EXPECT_NE(ok.out.find("orientation from the qform"), std::string::npos) << ok.out;
  // A vox_offset of 1e12 was read from byte 352 and exited 0.
  std::string far = nifti(4, 4, 4, 4, 16, 1.0f, voxels);
  const float offset = 1e12f;
  std::memcpy(&far[108], &offset, 4);
  for (const std::string name : {"far_offset.nii", "far_offset.nii.gz"}) {
    write_file(dir / name, name.ends_with(".gz") ? gzip(far) : far);
    expect_refused_new("volume info " + (dir / name).string(), {name, "vox_offset", "1e+12"},
                       dir / "none", dir / name);
  }
}

TEST_F(Hostile, ThePhantomIsFiniteAtEverySpacing) {
  // At 64 x 64 x 60 (and 64^3) voxels of 4 mm a voxel centre lies on the head's axis above the
  // vertex, where the phantom's surface ramp was 0/0: a NaN voxel its own reader then flagged.
  for (const std::string voxels : {"64,64,60", "64,64,64", "63,65,60"}) {
    const fs::path ct = dir / "phantom_4mm.nii.gz";
    const Outcome w = run("phantom -q --force --voxels " + voxels + " --spacing 4,4,4 -o " + ct.string());
    ASSERT_EQ(w.code, 0) << w.err;
    const Outcome r = run("volume info " + ct.string());
    EXPECT_EQ(r.code, 0) << r.err;
    EXPECT_EQ(r.out.find("not-a-number"), std::string::npos) << voxels << ":\n" << r.out;
  }
}

TEST_F(Hostile, NiftiIsReadFromTheFileGivenNotASameNamedOne) {
  // a.nii.gz holds zeros; a different a.nii beside it holds 5s: the voxels come from a.nii.gz.
  fs::create_directories(dir / "same_name");
  const fs::path gz = dir / "same_name" / "a.nii.gz", plain = dir / "same_name" / "a.nii";
  write_file(gz, gzip(nifti(4, 4, 4, 4, 16, 1.0f, std::string(128, '\0'))));
  std::string fives(128, '\0');
  for (std::size_t i = 0; i < fives.size(); i += 2) fives[i] = 5;
  write_file(plain, nifti(4, 4, 4, 4, 16, 1.0f, fives));
  Outcome r = run("volume info " + gz.string());
  EXPECT_EQ(r.code, 0) << r.err;
  EXPECT_NE(r.out.find("values     0 .. 0"), std::string::npos) << r.out;
  r = run("volume info " + plain.string());
  EXPECT_NE(r.out.find("values     5 .. 5"), std::string::npos) << r.out;
}

TEST_F(Hostile, NrrdSpacingThatIsNotANumberIsRefused) {
  // teem reads "nan" as an unknown spacing, which caps used to take as 1 mm.
  const std::string raw(4 * 4 * 4 * 2, '\0');
  const fs::path nrrd = dir / "nan_spacing.nrrd";
  write_file(nrrd, "NRRD0004\ntype: short\ndimension: 3\nsizes: 4 4 4\nspacings: nan 1 1\n"
                   "encoding: raw\nendian: little\n\n" + raw);
  expect_refused_new("volume info " + nrrd.string(), {"nan_spacing.nrrd", "spacings", "finite"},
                     dir / "none", nrrd);
  write_file(nrrd, "NRRD0004\ntype: short\ndimension: 3\nsizes: 4 4 4\nspace: "
                   "left-posterior-superior\nspace directions: (1,0,0) (0,NaN,0) (0,0,1)\n"
                   "encoding: raw\nendian: little\n\n" + raw);
  expect_refused_new("volume info " + nrrd.string(), {"nan_spacing.nrrd", "space directions"},
                     dir / "none", nrrd);
  // The same with numbers is read.
  write_file(nrrd, "NRRD0004\ntype: short\ndimension: 3\nsizes: 4 4 4\nspacings: 2 1 1\n"
                   "encoding: raw\nendian: little\n\n" + raw);
  EXPECT_EQ(run("volume info " + nrrd.string()).code, 0);
}

TEST_F(Hostile, DetachedNrrdDataLargerThanTheHeaderSaysIsRefused) {
  // 4 x 4 x 4 shorts are 128 bytes; the data file holds 256 (e.g. a 4 x 4 x 8 volume).
  const fs::path folder = dir / "detached";
  fs::create_directories(folder);
  write_file(folder / "data.raw", std::string(256, '\1'));
  const fs::path nhdr = folder / "liar.nhdr";
  write_file(nhdr, "NRRD0004\ntype: short\ndimension: 3\nsizes: 4 4 4\nspacings: 1 1 1\n"
                   "encoding: raw\nendian: little\ndata file: data.raw\n");
  expect_refused_new("volume info " + nhdr.string(), {"liar.nhdr", "data.raw", "256 bytes", "128"},
                     dir / "none", folder);
  // Exactly the size the header says is read.
  write_file(folder / "data.raw", std::string(128, '\1'));
  EXPECT_EQ(run("volume info " + nhdr.string()).code, 0);
  // A "data file" pattern reaches teem's sprintf only as a plain %d pattern.
  write_file(nhdr, "NRRD0004\ntype: short\ndimension: 3\nsizes: 4 4 4\nspacings: 1 1 1\n"
                   "encoding: raw\nendian: little\ndata file: slice%n%s%d.raw 1 4 1 2\n");
  expect_refused_new("volume info " + nhdr.string(), {"liar.nhdr", "data file", "%d"},
                     dir / "none", folder);
}

// ---- files the system refuses to open, odd names, killed runs

// Runs `caps args` as the user nobody when the tests run as root (root reads any file), so that
// a file without read permission is unreadable.
Outcome run_unprivileged(const fs::path& dir, const std::string& args) {
  const std::string as = ::geteuid() == 0 ? "setpriv --reuid=65534 --regid=65534 --clear-groups " : "";
  const fs::path out = dir / "stdout.txt", err = dir / "stderr.txt";
  const int status = std::system((as + CAPS_EXE + " " + args + " >" + out.string() + " 2>" +
                                  err.string() + " </dev/null").c_str());
  return {WIFEXITED(status) ? WEXITSTATUS(status) : -1, slurp(out), slurp(err)};
}

TEST_F(Hostile, PermissionDeniedAndSymlinkLoopsAreReportedAsSuch) {
  // A symbolic link loop: a volume, a scan, a model folder, a plan.
  const fs::path loops = dir / "loops";
  fs::create_directories(loops);
  for (const std::string name : {"ct.nii", "scan.ply", "model", "plan.json"}) {
    fs::remove(loops / name);
    fs::create_symlink(name, loops / name);  // points at itself
  }
  // What must stay unchanged (a snapshot cannot walk the loops themselves).
  const fs::path kept = loops / "README";
  write_file(kept, "links that point at themselves\n");
  expect_refused_new("volume info " + (loops / "ct.nii").string(), {"ct.nii", "symbolic link loop"},
                     dir / "none", kept);
  expect_refused_new("model from-scan " + (loops / "scan.ply").string() + " --thickness 6 -o " +
                         (dir / "loop_out").string(),
                     {"scan.ply", "symbolic link loop"}, dir / "loop_out", kept);
  expect_refused_new("model info " + (loops / "model").string(), {"model", "symbolic link loop"},
                     dir / "none", kept);
  expect_refused_new("plan check " + (loops / "plan.json").string(),
                     {"plan.json", "symbolic link loop"}, dir / "none", kept);
  // A file without read permission: not a damaged header, not a missing file.
  const fs::path locked = dir / "locked";
  fs::create_directories(locked);
  fs::permissions(locked, fs::perms::all);
  fs::permissions(dir, fs::perms::owner_all | fs::perms::group_read | fs::perms::group_exec |
                           fs::perms::others_read | fs::perms::others_exec);
  write_file(locked / "ct.nii", nifti(4, 4, 4, 4, 16, 1.0f, std::string(128, '\0')));
  write_file(locked / "scan.ply", "ply\nformat ascii 1.0\nend_header\n");
  fs::create_directories(locked / "model");
  for (const std::string name : {"ct.nii", "scan.ply", "model"})
    fs::permissions(locked / name, fs::perms::owner_write);
  for (const auto& [args, file] : std::vector<std::pair<std::string, std::string>>{
           {"volume info " + (locked / "ct.nii").string(), "ct.nii"},
           {"model from-scan " + (locked / "scan.ply").string() + " --thickness 6 -o " +
                (locked / "out").string(), "scan.ply"},
           {"model info " + (locked / "model").string(), "model"}}) {
    const Outcome r = run_unprivileged(dir, args);
    EXPECT_EQ(r.code, 2) << args << "\n" << r.err;
    EXPECT_NE(r.err.find(file), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("permission denied"), std::string::npos) << args << "\n" << r.err;
    EXPECT_EQ(r.err.find("internal error"), std::string::npos) << r.err;
  }
  EXPECT_FALSE(fs::exists(locked / "out"));
  for (const std::string name : {"ct.nii", "scan.ply", "model"})
    fs::permissions(locked / name, fs::perms::owner_all);
}

TEST_F(Hostile, TemporariesOfAKilledRunAreRemovedByTheNextRun) {
  // A run killed while writing leaves <output>.tmp-<pid>-<hex>: a folder, or a file, and the
  // .old of a replacement. The next run writing the same output removes those of dead processes
  // (pid 4194305 is above Linux's largest pid) and keeps those of a live one (this test's).
  const fs::path out = dir / "box_out";
  const std::string dead = "box_out.tmp-4194305-", live = "box_out.tmp-" + std::to_string(::getpid()) + "-";
  fs::create_directories(dir / (dead + "1a2b") / "sub");
  write_file(dir / (dead + "1a2b") / "sub" / "mesh.vtu", "partial");
  write_file(dir / (dead + "3c4d"), "partial file");
  fs::create_directories(dir / (dead + "5e6f.old"));
  fs::create_directories(dir / (live + "7a8b"));
  const Outcome r = run("fem box -q -o " + out.string() + " --cells 2,1,1");
  EXPECT_EQ(r.code, 0) << r.err;
  EXPECT_TRUE(fs::exists(out / "mesh.json"));
  for (const std::string& name : {dead + "1a2b", dead + "3c4d", dead + "5e6f.old"})
    EXPECT_FALSE(fs::exists(dir / name)) << name << " was left behind";
  EXPECT_TRUE(fs::exists(dir / (live + "7a8b"))) << "a live run's temporary was removed";
  fs::remove_all(dir / (live + "7a8b"));
  // A run really killed (SIGKILL) in the middle of writing a model, then the same command again.
  const fs::path model_out = dir / "killed_model";
  const std::string cmd = std::string(CAPS_EXE) + " model from-volume -q " + phantom().string() +
                          " -o " + model_out.string() + " --n-theta 96 --n-z 48 >/dev/null 2>&1 & "
                          "pid=$!; sleep 1; kill -9 $pid; wait $pid";
  std::system(cmd.c_str());
  const Outcome again = run("model from-volume -q " + phantom().string() + " -o " +
                            model_out.string() + " --n-theta 96 --n-z 48 --force");
  EXPECT_EQ(again.code, 0) << again.err;
  for (const auto& e : fs::directory_iterator(dir))
    EXPECT_EQ(e.path().filename().string().find("killed_model.tmp-"), std::string::npos)
        << "left behind: " << e.path();
}

TEST_F(Hostile, FileNamesThatAreNotUtf8AreHandled) {
  // Latin-1 names (a byte 0xE9), as an old workstation may write them.
  const fs::path folder = dir / "latin1";
  fs::create_directories(folder);
  const fs::path ct = folder / "caf\xe9.nii";
  fs::copy_file(phantom(), folder / "p.nii.gz", fs::copy_options::overwrite_existing);
  write_file(ct, nifti(8, 8, 8, 4, 16, 1.0f, std::string(8 * 8 * 8 * 2, '\0')));
  Outcome r = run("volume info " + ct.string() + " --json");
  EXPECT_EQ(r.code, 0) << r.err;
  EXPECT_EQ(r.err.find("internal error"), std::string::npos) << r.err;
  EXPECT_TRUE(nlohmann::json::accept(r.out)) << r.out;
  const fs::path model = folder / "mod\xe8le";
  r = run("model from-volume -q " + (folder / "p.nii.gz").string() + " -o " + model.string() +
          " --n-theta 96 --n-z 48 --json");
  EXPECT_EQ(r.code, 0) << r.err;
  EXPECT_EQ(r.err.find("internal error"), std::string::npos) << r.err;
  EXPECT_TRUE(nlohmann::json::accept(slurp(model / "model.json")));
  r = run("model info " + model.string() + " --json");
  EXPECT_EQ(r.code, 0) << r.err;
  EXPECT_TRUE(nlohmann::json::accept(r.out)) << r.out;
}

// ---- plans and outputs: a small model, a plan and a box mesh

class HostileModel : public Hostile {
 protected:
  static fs::path model() {
    const fs::path m = dir / "model";
    if (!fs::exists(m)) {
      const Outcome r = run("model from-volume -q " + phantom().string() + " -o " + m.string() +
                            " --n-theta 96 --n-z 48");
      EXPECT_EQ(r.code, 0) << r.err;
    }
    return m;
  }
  static fs::path plan() {
    const fs::path p = dir / "plan.json";
    if (!fs::exists(p)) {
      const Outcome r = run("plan new z-plasty -q --model " + model().string() + " --at 0,60 -o " + p.string());
      EXPECT_EQ(r.code, 0) << r.err;
    }
    return p;
  }
};

TEST_F(HostileModel, PlanPointsFarOutsideAHeadAreRefused) {
  std::string text = slurp(plan());
  const auto at = text.find("\"theta_deg\"", text.find("\"points\""));
  ASSERT_NE(at, std::string::npos);
  const auto value = text.find(':', at) + 1, end = text.find_first_of(",}", value);
  text.replace(value, end - value, " 1e300");
  const fs::path far = dir / "far_plan.json";
  write_file(far, text);
  expect_refused_new("plan check " + far.string(), {"point 0", "1e+300", "outside"},
                     dir / "none", far);
}

TEST_F(HostileModel, AnOutputThatIsOrHoldsAnInputIsRefusedEvenWithForce) {
  // solve mesh -o mesh
  const fs::path mesh = dir / "box_mesh";
  ASSERT_EQ(run("fem box -q -o " + mesh.string() + " --cells 2,1,1").code, 0);
  expect_refused("solve " + mesh.string() + " -o " + mesh.string() + " --force",
                 {mesh.string(), "is the input", "--force"}, mesh, mesh);
  // plan show p.json -o p.json
  const fs::path p = plan();
  expect_refused("plan show " + p.string() + " -o " + p.string() + " --force",
                 {p.string(), "is the input"}, p, p);
  // simulate --model M -o M
  const fs::path m = model();
  expect_refused("simulate --model " + m.string() + " --plan " + p.string() + " -o " + m.string() +
                     " --force",
                 {m.string(), "--model"}, m, m);
  // model from-scan model/skin.ply -o model
  ASSERT_TRUE(fs::exists(m / "skin.ply"));
  expect_refused("model from-scan " + (m / "skin.ply").string() + " --thickness 6 -o " +
                     m.string() + " --force",
                 {m.string(), "holds the input", "skin.ply"}, m, m);
  // The same through a different spelling of the path.
  expect_refused("solve " + mesh.string() + "/. -o " + (mesh.parent_path() / "." / "box_mesh").string() +
                     " --force",
                 {"is the input"}, mesh, mesh);
}

// ---- outputs: what --force may replace, one writer at a time, interrupted runs

// A caps run in the background (its stderr in `err`): its process id.
pid_t start_caps(const std::string& args, const fs::path& err) {
  const std::string cmd = "exec " + std::string(CAPS_EXE) + " " + args + " >/dev/null 2>" +
                          err.string() + " </dev/null";
  const pid_t pid = ::fork();
  if (pid == 0) {
    ::execl("/bin/sh", "sh", "-c", cmd.c_str(), static_cast<char*>(nullptr));
    ::_exit(127);
  }
  return pid;
}

// Waits up to `seconds` for an entry of `dir` whose name starts with `prefix`.
bool wait_for_entry(const fs::path& dir, const std::string& prefix, double seconds) {
  for (int i = 0; i < seconds * 20; ++i) {
    for (const auto& e : fs::directory_iterator(dir))
      if (e.path().filename().string().rfind(prefix, 0) == 0) return true;
    ::usleep(50000);
  }
  return false;
}

// Waits until the background run `pid` holds its claim `claim` and stops it there (SIGSTOP), so
// that what the test does next happens while the run is writing, however fast the run is. The
// claim file is created before it is locked, and the run writes its process number into it only
// once the lock is held: a run stopped between the two would let the other run take the output
// (in CI on 7 December 2026 the second run won that gap).
bool pause_when_claimed(pid_t pid, const fs::path& claim) {
  const std::string holder = std::to_string(pid) + "\n";
  for (int i = 0; i < 30000; ++i) {
    std::ifstream in(claim);
    const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    if (text == holder) return ::kill(pid, SIGSTOP) == 0;
    ::usleep(2000);
  }
  return false;
}

int exit_code_of(pid_t pid) {
  int status = 0;
  ::waitpid(pid, &status, 0);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

std::vector<std::string> entries_starting(const fs::path& dir, const std::string& prefix) {
  std::vector<std::string> found;
  for (const auto& e : fs::directory_iterator(dir))
    if (e.path().filename().string().rfind(prefix, 0) == 0) found.push_back(e.path().filename());
  return found;
}

TEST_F(HostileModel, ForceReplacesOnlyAFileOrAFolderCapsWrote) {
  // As root, `plan show p.json -o /dev/null --force` replaced /dev/null with a PNG; a FIFO made
  // here stands for it (the tests do not run as root).
  const fs::path p = plan();
  const fs::path fifo = dir / "out_fifo";
  fs::remove(fifo);
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0644), 0);
  expect_refused("plan show " + p.string() + " --model " + model().string() + " -o " +
                     fifo.string() + " --force",
                 {"out_fifo", "FIFO", "--force"}, fifo, p);
  EXPECT_TRUE(fs::is_fifo(fs::symlink_status(fifo))) << "the FIFO was replaced";
  expect_refused("plan new z-plasty -q --model " + model().string() + " --at 0,60 -o " +
                     fifo.string() + " --force",
                 {"out_fifo", "FIFO"}, fifo, p);
  EXPECT_TRUE(fs::is_fifo(fs::symlink_status(fifo)));
  // A symbolic link to a file elsewhere: neither the link nor its target is replaced.
  const fs::path target = dir / "link_target.png", link = dir / "out_link.png";
  write_file(target, "the user's picture");
  fs::remove(link);
  fs::create_symlink(target, link);
  expect_refused("plan show " + p.string() + " --model " + model().string() + " -o " +
                     link.string() + " --force",
                 {"out_link.png", "symbolic link"}, link, target);
  EXPECT_TRUE(fs::is_symlink(fs::symlink_status(link)));
  // A folder caps did not write (the user's documents) is not replaced by a folder output.
  const fs::path docs = dir / "documents";
  fs::create_directories(docs);
  write_file(docs / "letter.txt", "keep me");
  expect_refused("fem box -q -o " + docs.string() + " --cells 2,1,1 --force",
                 {"documents", "caps did not write"}, docs, docs);
  // What caps wrote is replaced: a file and a folder.
  const fs::path png = dir / "replaced.png", box = dir / "replaced_box";
  write_file(png, "old");
  EXPECT_EQ(run("plan show -q " + p.string() + " --model " + model().string() + " -o " +
                png.string() + " --force").code, 0);
  EXPECT_NE(slurp(png), "old");
  ASSERT_EQ(run("fem box -q -o " + box.string() + " --cells 2,1,1").code, 0);
  EXPECT_EQ(run("fem box -q -o " + box.string() + " --cells 3,1,1 --force").code, 0);
  EXPECT_NE(slurp(box / "mesh.json").find("\"elements\": 3"), std::string::npos);
}

TEST_F(HostileModel, ASecondWriterOfTheSameOutputIsRefusedNotRaced) {
  // Two runs writing the same -o without --force both exited 0, the later replacing the earlier.
  const fs::path out = dir / "claimed_model", err = dir / "claim_first.err";
  fs::remove_all(out);
  const std::string args = "model from-volume -q " + phantom().string() + " -o " + out.string() +
                           " --n-theta 96 --n-z 48";
  const pid_t first = start_caps(args, err);
  ASSERT_TRUE(pause_when_claimed(first, dir / "claimed_model.caps-claim"))
      << "the first run never started";
  if (fs::exists(out)) ::kill(first, SIGCONT);
  ASSERT_FALSE(fs::exists(out)) << "the first run had finished before it was paused";
  const Outcome second = run(args);
  EXPECT_EQ(second.code, 2) << second.err;
  EXPECT_NE(second.err.find("another caps run"), std::string::npos) << second.err;
  EXPECT_NE(second.err.find(std::to_string(first)), std::string::npos) << second.err;
  // --force does not take it either while the first run writes it.
  EXPECT_EQ(run(args + " --force").code, 2);
  ::kill(first, SIGCONT);
  EXPECT_EQ(exit_code_of(first), 0) << slurp(err);
  EXPECT_TRUE(fs::exists(out / "model.json"));
  EXPECT_TRUE(entries_starting(dir, "claimed_model.").empty());
  // A folder another program makes while a run writes the same name is left alone (the
  // finished output is moved into place only if the name is still free).
  const fs::path out2 = dir / "raced_model";
  fs::remove_all(out2);
  const pid_t run2 = start_caps("model from-volume -q " + phantom().string() + " -o " +
                                    out2.string() + " --n-theta 96 --n-z 48",
                                err);
  ASSERT_TRUE(pause_when_claimed(run2, dir / "raced_model.caps-claim"));
  if (fs::exists(out2)) ::kill(run2, SIGCONT);
  ASSERT_FALSE(fs::exists(out2)) << "the run had finished before it was paused";
  fs::create_directories(out2);
  write_file(out2 / "theirs.txt", "made meanwhile");
  ::kill(run2, SIGCONT);
  EXPECT_EQ(exit_code_of(run2), 2) << slurp(err);
  EXPECT_NE(slurp(err).find("raced_model"), std::string::npos) << slurp(err);
  EXPECT_EQ(slurp(out2 / "theirs.txt"), "made meanwhile");
  EXPECT_FALSE(fs::exists(out2 / "model.json"));
  EXPECT_TRUE(entries_starting(dir, "raced_model.").empty()) << entries_starting(dir, "raced_model.")[0];
}

TEST_F(HostileModel, InterruptedRunsRemoveTheirTemporaryAndSaySo) {
  // Ctrl-C or SIGTERM during caps simulate (--render too) died without a word and left
  // OUT.tmp-PID-hex behind.
  const std::string sim = "simulate -q --model " + model().string() + " --plan " + plan().string();
  for (const auto& [extra, sig, code, name] :
       std::vector<std::tuple<std::string, int, int, std::string>>{
           {"", SIGINT, 130, "SIGINT"},
           {" --render", SIGTERM, 143, "SIGTERM"},
           {" --domain patch --render", SIGINT, 130, "SIGINT"}}) {
    const fs::path out = dir / "interrupted_sim", err = dir / "interrupted.err";
    fs::remove_all(out);
    const pid_t pid = start_caps(sim + extra + " -o " + out.string(), err);
    ASSERT_TRUE(wait_for_entry(dir, "interrupted_sim.tmp-", 60)) << slurp(err);
    ::usleep(300000);
    ::kill(pid, sig);
    EXPECT_EQ(exit_code_of(pid), code) << extra << "\n" << slurp(err);
    const std::string message = slurp(err);
    EXPECT_NE(message.find("interrupted by " + name), std::string::npos) << message;
    EXPECT_NE(message.find("interrupted_sim"), std::string::npos) << message;
    EXPECT_FALSE(fs::exists(out));
    EXPECT_TRUE(entries_starting(dir, "interrupted_sim.").empty())
        << "left behind: " << entries_starting(dir, "interrupted_sim.")[0];
  }
  // A single-file output (the phantom) interrupted while it is written.
  const fs::path ct = dir / "interrupted.nii.gz", err = dir / "interrupted_ct.err";
  const pid_t pid = start_caps("phantom -q -o " + ct.string() + " --voxels 400,400,400 --spacing 0.6,0.6,0.6", err);
  ASSERT_TRUE(wait_for_entry(dir, "interrupted.nii.gz.caps-claim", 30));
  ::usleep(500000);
  ::kill(pid, SIGTERM);
  EXPECT_EQ(exit_code_of(pid), 143) << slurp(err);
  EXPECT_FALSE(fs::exists(ct));
  EXPECT_TRUE(entries_starting(dir, "interrupted.nii.gz").empty());
}

TEST_F(HostileModel, SizesThatAskForTooMuchAreRefusedBeforeTheWork) {
  // --mesh-size 0.01 ran for minutes with growing memory, 1e-10 ended in "internal error:
  // map::at"; a model grid of 8192 x 8192 asked 9.5 GB and failed after trying.
  const std::string m = model().string(), p = plan().string();
  const fs::path out = dir / "budget_mesh";
  for (const std::string size : {"0.01", "1e-10"}) {
    const auto start = std::chrono::steady_clock::now();
    expect_refused_new("mesh --model " + m + " --plan " + p + " -o " + out.string() +
                           " --mesh-size " + size,
                       {"--mesh-size " + size, "elements", "--max-elements"}, out, dir / "plan.json");
    expect_refused_new("simulate --model " + m + " --plan " + p + " -o " + out.string() +
                           " --mesh-size " + size,
                       {"--mesh-size " + size, "elements", "--max-elements"}, out, dir / "plan.json");
    EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(), 30);
  }
  for (const std::string size : {"0", "-1", "nan"})
    expect_refused_new("mesh --model " + m + " --plan " + p + " -o " + out.string() +
                           " --mesh-size " + size, {"--mesh-size"}, out, dir / "plan.json");
  // The budget is an option: the default mesh under a limit of 100 elements.
  expect_refused_new("mesh --model " + m + " --plan " + p + " -o " + out.string() +
                         " --max-elements 100", {"--max-elements", "100"}, out, dir / "plan.json");
  EXPECT_EQ(run("mesh -q --model " + m + " --plan " + p + " -o " + out.string()).code, 0);
  // The sensitivity map's closures, from its template's size.
  expect_refused_new("model sensitivity " + m + " --theta -30,30,30 --z 40,60,20 --mesh-size 0.01 -o " +
                         out.string() + "_map",
                     {"--mesh-size 0.01", "--max-elements"}, dir / "budget_mesh_map", dir / "plan.json");
  // The model's grid.
  const fs::path grid = dir / "budget_model";
  const auto start = std::chrono::steady_clock::now();
  expect_refused_new("model from-volume " + phantom().string() + " -o " + grid.string() +
                         " --n-theta 8192 --n-z 8192",
                     {"8192", "GB", "max_bytes"}, grid, phantom());
  EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(), 10);
  expect_refused_new("model from-volume " + phantom().string() + " -o " + grid.string() +
                         " --n-theta 512 --n-z 256 --max-bytes 1e6",
                     {"512", "max_bytes"}, grid, phantom());
}

TEST_F(HostileModel, BadInputsAreInputErrorsNotInternalOnes) {
  // These ended as "internal error" (exit 1).
  // An OBJ whose texture (its material's map_Kd, or --texture) is a folder.
  const fs::path obj = dir / "folder_texture.obj", folder = dir / "texture_folder";
  fs::create_directories(folder);
  write_file(obj, "mtllib folder_texture.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\n"
                  "vt 0 1\nusemtl a\nf 1/1 2/2 3/3\n");
  write_file(dir / "folder_texture.mtl", "newmtl a\nmap_Kd texture_folder\n");
  const fs::path out = dir / "bad_input_out";
  expect_refused_new("model from-scan " + obj.string() + " --thickness 6 -o " + out.string(),
                     {"texture_folder", "folder"}, out, obj);
  expect_refused_new("model from-scan " + obj.string() + " --thickness 6 --texture " +
                         folder.string() + " -o " + out.string(),
                     {"texture_folder", "folder"}, out, obj);
  // A model.json whose source lacks its path.
  const fs::path m = dir / "no_source_path";
  fs::remove_all(m);
  fs::copy(model(), m, fs::copy_options::recursive);
  nlohmann::json j = nlohmann::json::parse(slurp(m / "model.json"));
  j["source"].erase("path");
  write_file(m / "model.json", j.dump(1));
  expect_refused_new("model info " + m.string(), {"model.json", "source.path", "missing"},
                     dir / "none", m);
  // A mesh inverted from the start (mirrored through z = 0): a bad file, not a failed solve.
  const fs::path mesh = dir / "inverted_mesh";
  fs::remove_all(mesh);
  ASSERT_EQ(run("fem box -q -o " + mesh.string() + " --cells 2,1,1").code, 0);
  std::string vtu = slurp(mesh / "mesh.vtu");
  const auto points = vtu.find('>', vtu.find("Name=\"Points\"")) + 1;
  const auto end = vtu.find("</DataArray>", points);
  std::istringstream in(vtu.substr(points, end - points));
  std::string mirrored = "\n";
  for (double x, y, z; in >> x >> y >> z;)
    mirrored += std::to_string(x) + " " + std::to_string(y) + " " + std::to_string(-z) + "\n";
  vtu.replace(points, end - points, mirrored);
  write_file(mesh / "mesh.vtu", vtu);
  expect_refused_new("solve " + mesh.string() + " -o " + (dir / "inverted_result").string(),
                     {"mesh.vtu", "element 0", "inverted"}, dir / "inverted_result", mesh);
  // Sizes that would not fit: a box of 1e9 cells, a phantom of 2048^3 voxels (34 GB).
  expect_refused_new("fem box -o " + out.string() + " --cells 1000,1000,1000", {"--cells", "1e+09"},
                     out, mesh);
  expect_refused_new("phantom -o " + (dir / "huge_phantom.nii.gz").string() +
                         " --voxels 2048,2048,2048",
                     {"--voxels", "GB"}, dir / "huge_phantom.nii.gz", mesh);
}

TEST_F(HostileModel, PlanErrorsNameTheFileAndTheEntry) {
  // A plan whose path names a point it does not have, and one whose suture sews two points that
  // are not a border edge: every command reading the plan names the file and the entry.
  const nlohmann::json good = nlohmann::json::parse(slurp(plan()));
  nlohmann::json j = good;
  j["paths"][0][1] = 99;
  const fs::path p = dir / "entry_plan.json";
  write_file(p, j.dump(1));
  expect_refused_new("plan check " + p.string(), {p.string() + ": ", "/paths/0/1", "names point 99"},
                     dir / "none", p);
  const fs::path out = dir / "entry_sim";
  expect_refused_new("simulate --model " + model().string() + " --plan " + p.string() + " -o " +
                         out.string(),
                     {p.string() + ": ", "/paths/0/1"}, out, p);
  j = good;
  j["sutures"][0][0] = {0, 2};
  write_file(p, j.dump(1));
  expect_refused_new("plan check " + p.string(), {p.string() + ": ", "/sutures/0", "(0,2)"},
                     dir / "none", p);
  expect_refused_new("mesh --model " + model().string() + " --plan " + p.string() + " -o " +
                         out.string(),
                     {p.string() + ": ", "/sutures/0", "(0,2)"}, out, p);
}

TEST_F(HostileModel, NamesThatAreNotUtf8AreRefusedWhereAJsonFileWouldRecordThem) {
  // result.json records the plan's and the model's names, a plan its model's folder: JSON is
  // UTF-8, so a Latin-1 name is refused before any work (the JSON writer threw at the end of the
  // solve before, an internal error; a plan recorded with U+FFFD could not find its model).
  const fs::path latin_plan = dir / "pl\xe4n.json";
  fs::copy_file(plan(), latin_plan, fs::copy_options::overwrite_existing);
  const fs::path out = dir / "latin_sim";
  expect_refused_new("simulate --model " + model().string() + " --plan " + latin_plan.string() +
                         " -o " + out.string(),
                     {"plan file", "pl\\xe4n.json", "not valid UTF-8", "rename"}, out, latin_plan);
  const fs::path latin_model = dir / "mod\xe8le_plan";
  fs::remove_all(latin_model);
  fs::copy(model(), latin_model, fs::copy_options::recursive);
  const fs::path new_plan = dir / "latin_model_plan.json";
  expect_refused_new("plan new z-plasty -q --model " + latin_model.string() + " --at 0,60 -o " +
                         new_plan.string(),
                     {"model folder", "mod\\xe8le_plan", "not valid UTF-8"}, new_plan, latin_model);
}

TEST_F(HostileModel, JsonFieldsOfTheWrongTypeAreInputErrors) {
  // A plan whose "format" is a number, or whose format_version is a string.
  const std::string text = slurp(plan());
  for (const auto& [from, to] : std::vector<std::pair<std::string, std::string>>{
           {"\"format\": \"caps-plan\"", "\"format\": 5"},
           {"\"format_version\": 1", "\"format_version\": \"1\""}}) {
    const auto at = text.find(from);
    ASSERT_NE(at, std::string::npos) << from;
    std::string bad = text;
    bad.replace(at, from.size(), to);
    const fs::path p = dir / "typed_plan.json";
    write_file(p, bad);
    expect_refused_new("plan check " + p.string(), {"typed_plan.json", "format"}, dir / "none", p);
  }
  // A model.json whose format_version is a string.
  const fs::path m = dir / "typed_model";
  fs::remove_all(m);
  fs::copy(model(), m, fs::copy_options::recursive);
  std::string mj = slurp(m / "model.json");
  const auto at = mj.find("\"format_version\": 1");
  ASSERT_NE(at, std::string::npos);
  mj.replace(at, std::string("\"format_version\": 1").size(), "\"format_version\": \"1\"");
  write_file(m / "model.json", mj);
  expect_refused_new("model info " + m.string(), {"model.json", "format_version"}, dir / "none", m);
  // files.r_skin = 5
  mj.replace(at, std::string("\"format_version\": \"1\"").size(), "\"format_version\": 1");
  const auto r_skin = mj.find("\"r_skin\": \"");
  ASSERT_NE(r_skin, std::string::npos);
  const auto value = r_skin + std::string("\"r_skin\": ").size();
  mj.replace(value, mj.find('"', value + 1) + 1 - value, "5");
  write_file(m / "model.json", mj);
  expect_refused_new("model info " + m.string(), {"model.json", "r_skin"}, dir / "none", m);
}

TEST_F(HostileModel, ABowTieFlapIsRefusedByThePlanCheck) {
  // The Z-plasty's four points listed around a flap in an order whose sides cross (a bow-tie):
  // of the three cyclic orders of four points, the one whose sides (a,b) and (c,d) or (b,c) and
  // (d,a) cross properly.
  nlohmann::json j = nlohmann::json::parse(slurp(plan()));
  std::vector<std::array<double, 2>> p;
  for (const auto& x : j["points"]) p.push_back({x["theta_deg"].get<double>(), x["z_mm"].get<double>()});
  ASSERT_GE(p.size(), 4u);
  auto side = [&](int a, int b, int c) {
    return (p[b][0] - p[a][0]) * (p[c][1] - p[a][1]) - (p[b][1] - p[a][1]) * (p[c][0] - p[a][0]);
  };
  auto cross = [&](int a, int b, int c, int d) {
    return side(a, b, c) * side(a, b, d) < 0 && side(c, d, a) * side(c, d, b) < 0;
  };
  std::vector<int> bow;
  for (const auto& order : std::vector<std::vector<int>>{{0, 1, 2, 3}, {0, 2, 1, 3}, {0, 1, 3, 2}})
    if (cross(order[0], order[1], order[2], order[3]) || cross(order[1], order[2], order[3], order[0]))
      bow = order;
  ASSERT_FALSE(bow.empty()) << "no bow-tie order among the first four points";
  j["flaps"] = nlohmann::json::array({bow});
  const fs::path bad = dir / "bowtie_plan.json";
  write_file(bad, j.dump(1));
  expect_refused_new("plan check " + bad.string(), {"flap 0", "crosses itself", "bow-tie"},
                     dir / "none", bad);
  // The same four points in a crossing-free order are accepted.
  std::vector<int> ok = bow;
  std::swap(ok[1], ok[2]);
  if (cross(ok[0], ok[1], ok[2], ok[3]) || cross(ok[1], ok[2], ok[3], ok[0])) std::swap(ok[2], ok[3]);
  j["flaps"] = nlohmann::json::array({ok});
  write_file(bad, j.dump(1));
  const Outcome r = run("plan check " + bad.string());
  EXPECT_EQ(r.err.find("flap 0"), std::string::npos) << r.err;
}

TEST_F(HostileModel, JsonFieldsAreCheckedAndNamed) {
  // Plans: indices that are not whole numbers, or beyond int; a number of the wrong type.
  const nlohmann::json good = nlohmann::json::parse(slurp(plan()));
  const fs::path p = dir / "schema_plan.json";
  for (const auto& [pointer, value, words] :
       std::vector<std::tuple<std::string, nlohmann::json, std::vector<std::string>>>{
           {"/paths/0/1", 1.5, {"paths[0][1]", "1.5", "whole number"}},
           {"/paths/0/0", 1e300, {"paths[0][0]", "1e+300"}},
           {"/sutures/0/0/0", -1e20, {"sutures", "whole number"}},
           {"/points/1/z_mm", "sixty", {"/points/1/z_mm", "number"}},
           {"/frame/theta_deg", nlohmann::json::array(), {"/frame/theta_deg"}}}) {
    nlohmann::json j = good;
    j[nlohmann::json::json_pointer(pointer)] = value;
    write_file(p, j.dump(1));
    expect_refused_new("plan check " + p.string(), words, dir / "none", p);
  }
  // model.json: counts and the grid.
  const fs::path m = dir / "schema_model";
  const nlohmann::json mj = nlohmann::json::parse(slurp(model() / "model.json"));
  for (const auto& [pointer, value, words] :
       std::vector<std::tuple<std::string, nlohmann::json, std::vector<std::string>>>{
           {"/grid/n_theta", 1e300, {"model.json", "grid.n_theta", "whole number"}},
           {"/statistics/cells", -1, {"model.json", "statistics.cells", "not a count"}},
           {"/meshes/skin/faces", 2.5, {"model.json", "meshes.skin.faces"}},
           {"/axis/origin_lps", "here", {"model.json", "/axis/origin_lps"}}}) {
    fs::remove_all(m);
    fs::copy(model(), m, fs::copy_options::recursive);
    nlohmann::json j = mj;
    j[nlohmann::json::json_pointer(pointer)] = value;
    write_file(m / "model.json", j.dump(1));
    expect_refused_new("model info " + m.string(), words, dir / "none", m);
  }
  // mesh.json and mesh.vtu: indices and connectivity that are not whole numbers.
  const fs::path mesh = dir / "schema_mesh";
  fs::remove_all(mesh);
  ASSERT_EQ(run("fem box -q -o " + mesh.string() + " --cells 2,1,1").code, 0);
  const std::string json_text = slurp(mesh / "mesh.json"), vtu = slurp(mesh / "mesh.vtu");
  for (const auto& [pointer, value, words] :
       std::vector<std::tuple<std::string, nlohmann::json, std::vector<std::string>>>{
           {"/fixed_nodes/0", 1e300, {"mesh.json", "fixed_nodes[0]", "whole number"}},
           {"/sutures", nlohmann::json::array({{0.5, 1}}), {"mesh.json", "sutures[0][0]"}},
           {"/materials/0/parameters/E", "soft", {"mesh.json", "material of layer 0", "parameter E must be a number"}}}) {
    nlohmann::json j = nlohmann::json::parse(json_text);
    j[nlohmann::json::json_pointer(pointer)] = value;
    write_file(mesh / "mesh.json", j.dump(1));
    expect_refused_new("solve " + mesh.string() + " -o " + (dir / "schema_result").string(), words,
                       dir / "schema_result", mesh);
  }
  write_file(mesh / "mesh.json", json_text);
  // Connectivity 1 written as 1.5: a non-integer node id.
  const auto conn = vtu.find("Name=\"connectivity\"");
  ASSERT_NE(conn, std::string::npos);
  const auto first = vtu.find('>', conn) + 1;
  std::string bad_vtu = vtu;
  bad_vtu.insert(vtu.find_first_of(" \n", vtu.find_first_not_of(" \n", first)), ".5");
  write_file(mesh / "mesh.vtu", bad_vtu);
  expect_refused_new("solve " + mesh.string() + " -o " + (dir / "schema_result").string(),
                     {"mesh.vtu", "connectivity[0]", "whole number"}, dir / "schema_result", mesh);
  write_file(mesh / "mesh.vtu", vtu);
}

TEST_F(HostileModel, NodalLoadsOfAbsurdSizeAreRefused) {
  const fs::path mesh = dir / "load_mesh";
  fs::remove_all(mesh);
  ASSERT_EQ(run("fem box -q -o " + mesh.string() + " --cells 2,1,1").code, 0);
  nlohmann::json j = nlohmann::json::parse(slurp(mesh / "mesh.json"));
  j["loads_n"] = nlohmann::json::array({{3, 0.0, 1e308, 0.0}});
  write_file(mesh / "mesh.json", j.dump(1));
  expect_refused_new("solve " + mesh.string() + " -o " + (dir / "load_result").string(),
                     {"mesh.json", "loads_n[0]", "1e+308", "N"}, dir / "load_result", mesh);
  // A load of 1 N is solved.
  j["loads_n"] = nlohmann::json::array({{3, 0.0, 1.0, 0.0}});
  write_file(mesh / "mesh.json", j.dump(1));
  const Outcome r = run("solve -q " + mesh.string() + " -o " + (dir / "load_result").string());
  EXPECT_EQ(r.code, 0) << r.err;
}

}  // namespace
