// The caps program as a user runs it: help, exit codes, --json, refusing to clobber, and the
// catalogue of bad inputs (each exit code 2, a message naming the file, no output left behind).
#include <gtest/gtest.h>

#include "cli_outcome.hpp"
#include <sys/wait.h>
#include <unistd.h>

#include <array>
#include <cstring>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

namespace fs = std::filesystem;

namespace {

using caps_test::Outcome;
using caps_test::slurp;
using caps_test::write_file;

class Cli : public caps_test::CliTest {
 protected:
  static void SetUpTestSuite() { dir = caps_test::fresh_temp_dir("caps_cli_"); }
  // Expects a refusal: exit code 2, the message names `what`, and `output` was not created.
  static void expect_refused(const std::string& args, const std::string& what,
                             const fs::path& output) {
    const Outcome r = run(args);
    EXPECT_EQ(r.code, 2) << args << "\n" << r.err;
    EXPECT_NE(r.err.find(what), std::string::npos) << "message should name " << what << ":\n" << r.err;
    EXPECT_EQ(r.err.find("internal error"), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(output)) << output;
    for (const auto& e : fs::directory_iterator(output.parent_path()))
      EXPECT_EQ(e.path().filename().string().find(".tmp-"), std::string::npos)
          << "temporary left behind: " << e.path();
  }
};

}  // namespace

TEST_F(Cli, HelpShowsExamplesAndExitsZero) {
  Outcome r = run("--help");
  EXPECT_EQ(r.code, 0);
  EXPECT_NE(r.out.find("model"), std::string::npos);
  for (const char* cmd : {"model from-volume", "model info", "phantom", "volume info"}) {
    r = run(std::string(cmd) + " --help");
    EXPECT_EQ(r.code, 0) << cmd;
    EXPECT_NE(r.out.find("Example"), std::string::npos) << cmd << " --help has no example";
  }
}

TEST_F(Cli, UsageErrorsExitTwo) {
  EXPECT_EQ(run("").code, 2);
  EXPECT_EQ(run("no-such-command").code, 2);
  EXPECT_EQ(run("model from-volume").code, 2);  // INPUT and -o are required
  const Outcome r = run("model from-volume x.nii --skin-threshold abc -o " + (dir / "m").string());
  EXPECT_EQ(r.code, 2);
  EXPECT_NE(r.err.find("skin-threshold"), std::string::npos) << r.err;
}

TEST_F(Cli, PhantomToModelToInfoWithJson) {
  const fs::path model = dir / "model_json";
  Outcome r = run("model from-volume " + phantom().string() + " -o " + model.string() + " --json -q");
  ASSERT_EQ(r.code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["format_version"], 1);
  EXPECT_EQ(j["source"]["modality"], "CT");
  EXPECT_TRUE(r.err.empty()) << "--quiet must silence stderr: " << r.err;
  r = run("model info " + model.string() + " --json");
  ASSERT_EQ(r.code, 0) << r.err;
  EXPECT_EQ(nlohmann::json::parse(r.out)["grid"]["n_theta"], 512);
  r = run("model info " + model.string());
  EXPECT_EQ(r.code, 0);
  EXPECT_NE(r.out.find("thickness"), std::string::npos);
  // The same output again: refused without --force, untouched; replaced with it.
  const auto before = fs::last_write_time(model / "model.json");
  expect_refused("model from-volume " + phantom().string() + " -o " + model.string(), "--force",
                 dir / "never_created");
  EXPECT_EQ(fs::last_write_time(model / "model.json"), before);
  r = run("model from-volume " + phantom().string() + " -o " + model.string() + " --force -q");
  EXPECT_EQ(r.code, 0) << r.err;
  // Inputs are never modified.
  EXPECT_TRUE(fs::exists(phantom()));
}

TEST_F(Cli, AVolumeThatDoesNotSayItsModalityAndIsNoCtNeedsTheUserToSay) {
  // ch2 (a T1 MR in a NIfTI, which has no modality field): modelled as an MR, with its bone
  // assumed under the skin, only when the user says --modality MR; before, any such volume was
  // (a CT in other units too: issue 37).
  const fs::path ch2 = "/usr/share/mricron/templates/ch2.nii.gz";
  if (!fs::exists(ch2)) GTEST_SKIP() << "mricron-data not installed (scripts/setup.sh installs it)";
  const fs::path out = dir / "ch2_model";
  expect_refused("model from-volume " + ch2.string() + " -o " + out.string(), "--modality MR", out);
  const Outcome r = run("model from-volume -q " + ch2.string() + " --modality MR --no-tissue "
                        "--n-theta 64 --n-z 32 -o " + out.string());
  EXPECT_EQ(r.code, 0) << r.err;
  EXPECT_NE(slurp(out / "model.json").find("\"modality\": \"MR\""), std::string::npos);
}

TEST_F(Cli, BadVolumeInputsAreRefusedCleanly) {
  const fs::path out = dir / "out_model";
  auto refuse = [&](const fs::path& input, const std::string& extra = "") {
    expect_refused("model from-volume " + input.string() + " -o " + out.string() + " " + extra,
                   input.filename().string(), out);
  };
  // A missing file.
  refuse(dir / "missing.nii.gz");
  // Not an image: text with an image's name.
  write_file(dir / "notes.nii", "this is not a NIfTI file\n");
  refuse(dir / "notes.nii");
  // A truncated gzip NIfTI.
  {
    const std::string whole = slurp(phantom());
    write_file(dir / "truncated.nii.gz", whole.substr(0, whole.size() / 2));
    refuse(dir / "truncated.nii.gz");
  }
  // NRRD headers: data shorter than the header says, zero and absurd dimensions.
  write_file(dir / "short.raw", std::string(1000, '\0'));
  write_file(dir / "short.nhdr", "NRRD0004\ntype: short\ndimension: 3\nsizes: 64 64 64\n"
                                 "spacings: 1 1 1\nencoding: raw\nendian: little\ndata file: short.raw\n");
  refuse(dir / "short.nhdr");
  write_file(dir / "zero.nhdr", "NRRD0004\ntype: short\ndimension: 3\nsizes: 0 64 64\n"
                                "spacings: 1 1 1\nencoding: raw\nendian: little\ndata file: short.raw\n");
  refuse(dir / "zero.nhdr");
  write_file(dir / "absurd.nhdr", "NRRD0004\ntype: short\ndimension: 3\nsizes: 100000 100000 100000\n"
                                  "spacings: 1 1 1\nencoding: raw\nendian: little\ndata file: short.raw\n");
  refuse(dir / "absurd.nhdr");
  // An unknown extension.
  write_file(dir / "scan.xyz", "1 2 3\n");
  refuse(dir / "scan.xyz");
  // An empty folder, and a DICOM series with a slice missing.
  fs::create_directories(dir / "empty_dicom");
  refuse(dir / "empty_dicom");
  const fs::path ge = fs::path(CAPS_SHARED_DATA) / "ct" / "ge-head-tilt";
  if (fs::exists(ge)) {
    const fs::path gap = dir / "dicom_gap";
    fs::create_directories(gap);
    for (const auto& e : fs::directory_iterator(ge))
      if (e.path().extension() == ".dcm" && e.path().filename() != "10.dcm")
        fs::copy_file(e.path(), gap / e.path().filename());
    const Outcome r = run("model from-volume " + gap.string() + " -o " + out.string());
    EXPECT_EQ(r.code, 2);
    EXPECT_NE(r.err.find("missing"), std::string::npos) << r.err;
    EXPECT_NE(r.err.find("09.dcm"), std::string::npos) << r.err;
    EXPECT_FALSE(fs::exists(out));
  }
  // A volume with no head in it: air only.
  {
    std::string air(32 * 32 * 32 * 2, '\0');
    for (std::size_t i = 0; i < air.size(); i += 2) {
      const short v = -1000;
      std::memcpy(&air[i], &v, 2);
    }
    write_file(dir / "air.raw", air);
    write_file(dir / "air.nhdr", "NRRD0004\ntype: short\ndimension: 3\nsizes: 32 32 32\n"
                                 "spacings: 4 4 4\nencoding: raw\nendian: little\ndata file: air.raw\n");
    expect_refused("model from-volume " + (dir / "air.nhdr").string() + " --modality CT -o " +
                       out.string(), "no head found", out);
  }
}

TEST_F(Cli, BadOutputsAndOptionsAreRefusedCleanly) {
  const std::string in = phantom().string();
  // The output's parent folder does not exist; the output is an existing file.
  expect_refused("model from-volume " + in + " -o " + (dir / "no" / "such" / "m").string(),
                 "does not exist", dir / "no");
  write_file(dir / "a_file", "x");
  const Outcome r = run("model from-volume " + in + " -o " + (dir / "a_file").string() + " --force");
  EXPECT_EQ(r.code, 2);
  EXPECT_EQ(slurp(dir / "a_file"), "x");
  // Options out of range.
  const fs::path out = dir / "opt_model";
  expect_refused("model from-volume " + in + " -o " + out.string() + " --n-theta 3", "theta", out);
  expect_refused("model from-volume " + in + " -o " + out.string() + " --decimate 2", "--decimate", out);
  expect_refused("model from-volume " + in + " -o " + out.string() + " --axis-dir 0,0,0", "--axis-dir", out);
  expect_refused("model from-volume " + in + " -o " + out.string() + " --axis-origin 1,2", "--axis-origin", out);
  expect_refused("phantom -o " + (dir / "p.nii.gz").string() + " --size 0,0,0", "size", dir / "p.nii.gz");
  expect_refused("phantom -o " + (dir / "p.txt").string(), ".nii", dir / "p.txt");
  expect_refused("model info " + (dir / "nothing").string(), "nothing", dir / "nothing");
}

TEST_F(Cli, CylindricalRangeImageRoundTrip) {
  const fs::path model = dir / "model_for_range", range = dir / "range", back = dir / "from_range";
  ASSERT_EQ(run("model from-volume " + phantom().string() + " -o " + model.string() + " -q").code, 0);
  Outcome r = run("model export-range " + model.string() + " -o " + range.string());
  ASSERT_EQ(r.code, 0) << r.err;
  r = run("model from-scan " + (range / "range.json").string() + " --thickness 5 -o " + back.string() +
          " --json -q");
  ASSERT_EQ(r.code, 0) << r.err;
  const auto j = nlohmann::json::parse(r.out);
  EXPECT_EQ(j["source"]["kind"], "scan");
  EXPECT_EQ(j["thickness"]["kind"], "constant");
  // A sidecar without scales, and a colour image as the range image: refused cleanly.
  write_file(dir / "noscale.json", R"({"range": "range/range.png"})");
  expect_refused("model from-scan " + (dir / "noscale.json").string() + " --thickness 5 -o " +
                     (dir / "x").string(), "r_scale_mm", dir / "x");
  expect_refused("model from-scan " + (model / "thickness.png").string() +
                     " --r-scale 0.1 --z-scale 1 --thickness 5 -o " + (dir / "y").string(),
                 "grey", dir / "y");
}

TEST_F(Cli, AMeshInvertedBeforeAnyLoadIsABadFileNamingTheElement) {
  // Inverted before any load: the file is at fault (exit 2), not the solve (exit 1, as it was).
  const fs::path mesh = dir / "inverted_mesh";
  ASSERT_EQ(run("fem box -o " + mesh.string() + " --size 2,2,2 --cells 2,2,2 -q").code, 0);
  // Turn cell 0 inside out: swap its top and bottom faces (Hex20 nodes 0-3 with 4-7, 8-11
  // with 12-15) in mesh.vtu's connectivity, one line per cell.
  std::string vtu = slurp(mesh / "mesh.vtu");
  const std::string key = "Name=\"connectivity\" format=\"ascii\">\n";
  const auto at = vtu.find(key);
  ASSERT_NE(at, std::string::npos);
  const auto begin = at + key.size(), end = vtu.find('\n', begin);
  std::istringstream in(vtu.substr(begin, end - begin));
  std::array<long, 20> n{};
  for (long& id : n) in >> id;
  for (int k = 0; k < 4; ++k) {
    std::swap(n[k], n[4 + k]);
    std::swap(n[8 + k], n[12 + k]);
  }
  std::string line;
  for (std::size_t k = 0; k < n.size(); ++k)
    line += std::to_string(n[k]) + (k + 1 < n.size() ? " " : "");
  vtu.replace(begin, end - begin, line);
  write_file(mesh / "mesh.vtu", vtu);
  const fs::path out = dir / "inverted_result";
  const Outcome r = run("solve " + mesh.string() + " -o " + out.string() + " -q");
  EXPECT_EQ(r.code, 2) << r.err;
  EXPECT_EQ(r.err.rfind("caps: error: " + (mesh / "mesh.vtu").string() + ": element 0 (Hex20) is "
                        "inverted or degenerate before any load (Jacobian determinant", 0), 0u)
      << r.err;
  EXPECT_EQ(r.err.find("internal error"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(out));
}

TEST_F(Cli, RunsTheCpusOwnBlasKernelsAndKeepsTheUsers) {
  // OpenBLAS falls back to its generic SSE3 kernels (Prescott) on a CPU newer than it knows;
  // the caps program then starts itself again with the kernels the CPU runs (fem/blas.hpp), and
  // result.json names them. A kernel set the user gives in OPENBLAS_CORETYPE stays, and the
  // answer is the same to round-off either way.
  const fs::path mesh = dir / "blas_box";
  ASSERT_EQ(run("fem box -o " + mesh.string() + " --size 30,20,6 --cells 5,6,2 --slot -q").code, 0);
  const fs::path own = dir / "blas_own", given = dir / "blas_given";
  ASSERT_EQ(run("solve " + mesh.string() + " -o " + own.string() + " -q").code, 0);
  const Outcome r = caps_test::run_caps(
      dir, "solve " + mesh.string() + " -o " + given.string() + " -q", "OPENBLAS_CORETYPE=Prescott");
  ASSERT_EQ(r.code, 0) << r.err;
  const auto a = nlohmann::json::parse(slurp(own / "result.json"));
  const auto b = nlohmann::json::parse(slurp(given / "result.json"));
  const std::string kernels = a["blas_kernels"];
  if (kernels.empty()) GTEST_SKIP() << "the BLAS is not OpenBLAS";
  EXPECT_EQ(b["blas_kernels"], "Prescott");
  __builtin_cpu_init();
  if (__builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma"))
    for (const char* older : {"Prescott", "Core2", "Penryn", "Nehalem", "Sandybridge", "Barcelona"})
      EXPECT_NE(kernels, older) << "an AVX2 CPU runs OpenBLAS's generic kernels";
  const double fa = a["total_suture_force_n"], fb = b["total_suture_force_n"];
  EXPECT_NEAR(fa, fb, 1e-9 * std::abs(fb));
}

TEST_F(Cli, SolvesABoxInEitherPrecisionAndRefusesBadSolverOptions) {
  const fs::path mesh = dir / "box_mesh";
  ASSERT_EQ(run("fem box -o " + mesh.string() + " --size 30,20,6 --cells 5,6,2 --slot -q").code, 0);
  nlohmann::json results[2];
  const char* precision[2] = {"mixed", "double"};
  for (int k = 0; k < 2; ++k) {
    const fs::path out = dir / (std::string("box_result_") + precision[k]);
    const Outcome r = run("solve " + mesh.string() + " -o " + out.string() + " --precision " +
                          precision[k] + " -q");
    ASSERT_EQ(r.code, 0) << r.err;
    results[k] = nlohmann::json::parse(slurp(out / "result.json"));
    EXPECT_EQ(results[k]["precision"]["arithmetic"], precision[k]);
    // The finite-strain closure's tolerance (fem::NewtonOptions::residual_tolerance).
    EXPECT_LE(results[k]["relative_residual"].get<double>(), 1e-6);
  }
  EXPECT_GT(results[0]["precision"]["refinement_iterations"].get<int>(), 0);
  const double f0 = results[0]["total_suture_force_n"], f1 = results[1]["total_suture_force_n"];
  EXPECT_NEAR(f0, f1, 1e-9 * std::abs(f1));
  const fs::path out = dir / "box_result_bad";
  expect_refused("solve " + mesh.string() + " -o " + out.string() + " --precision half", "half", out);
  expect_refused("solve " + mesh.string() + " -o " + out.string() + " --solver lu", "lu", out);
  expect_refused("solve " + (dir / "no_mesh").string() + " -o " + out.string(), "no_mesh", out);
}
