// Landmarks through the caps program: `caps model from-volume` writes them into model.json,
// `caps model landmarks` recomputes and prints them, `caps plan new --at glabella+L,U` places a
// plan relative to one (at the analytic glabella of the face phantom for +0,0), and a landmark the
// model lacks is refused with exit 2.

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <nlohmann/json.hpp>
#include <sstream>

#include "cli_run.hpp"

namespace fs = std::filesystem;
using caps_test::caps;
using nlohmann::json;

namespace {

struct V3 {
  double x = 0, y = 0, z = 0;
};
double dist(const V3& a, const V3& b) { return std::sqrt((a.x - b.x) * (a.x - b.x) + (a.y - b.y) * (a.y - b.y) + (a.z - b.z) * (a.z - b.z)); }
V3 v3(const json& a) { return {a[0].get<double>(), a[1].get<double>(), a[2].get<double>()}; }

const fs::path kTmp = fs::temp_directory_path() / "caps_test_cli_landmarks";

json read_json(const fs::path& p) {
  std::ifstream in(p);
  return json::parse(in);
}

// The face phantom (1.5 mm voxels) and its model, built once, without the whole-face tissue
// model (--no-tissue): the landmarks are the same without it (model.json's landmarks compared,
// 6 December 2026), no test here closes a wound in the whole face, and it took 4.9 of
// from-volume's 7.1 s of CPU.
const fs::path& face_model() {
  static const fs::path dir = [] {
    fs::remove_all(kTmp);
    fs::create_directories(kTmp);
    const auto ph = caps("phantom --face --no-holder --voxels 160,160,150 --spacing 1.5,1.5,1.5 -o " +
                         (kTmp / "face.nii.gz").string() + " -q");
    EXPECT_EQ(ph.code, 0) << ph.out;
    const auto m = caps("model from-volume " + (kTmp / "face.nii.gz").string() + " -o " +
                        (kTmp / "face").string() + " --n-theta 512 --n-z 256 --no-tissue -q");
    EXPECT_EQ(m.code, 0) << m.out;
    return kTmp / "face";
  }();
  return dir;
}

// The phantom's analytic glabella (HeadPhantom with face: the brow's top on the midline), LPS:
// the maximum of its midline profile 95 sqrt(1 - (z/105)^2) + relief(0, z) for z in 15..40 mm,
// about the axis point (2, 6, 0) towards anterior (-y). Computed here from the formula of
// volume/src/phantom.cpp's face_relief().
V3 analytic_glabella() {
  auto g = [](double x) { return std::exp(-x * x); };
  auto profile = [&](double z) {
    const double head = 95.0 * std::sqrt(1.0 - (z / 105.0) * (z / 105.0));
    return head + 5.0 * g((z - 28.0) / 6.0) - 3.0 * g((z - 12.0) / 5.0) +
           16.0 * g((z + 12.0) / 9.0);
  };
  double best_z = 15, best = -1;
  for (double z = 15; z <= 40; z += 0.001)
    if (profile(z) > best) {
      best = profile(z);
      best_z = z;
    }
  return {2.0, 6.0 - best, best_z};
}

}  // namespace

TEST(CliLandmarks, FromVolumeWritesThemAndLandmarksPrintsThem) {
  const json m = read_json(face_model() / "model.json");
  ASSERT_TRUE(m.contains("landmarks"));
  for (const char* n : {"glabella", "nasion", "pronasale", "subnasale", "pogonion", "zygion_left",
                        "zygion_right", "exocanthion_left", "exocanthion_right", "tragion_left",
                        "tragion_right"}) {
    ASSERT_TRUE(m["landmarks"]["items"].contains(n)) << n;
    EXPECT_TRUE(m["landmarks"]["items"][n]["found"].get<bool>()) << n;
    // The phantom's soft tissue is 2.5 .. 8.5 mm under the head radius plus the relief: at least
    // a millimetre everywhere (1.9 mm at the subnasale's dip, along the normal).
    EXPECT_GT(m["landmarks"]["items"][n]["thickness_mm"].get<double>(), 1.0) << n;
  }
  const auto gl = m["landmarks"]["items"]["glabella"]["lps"];
  const V3 p = v3(gl);
  EXPECT_LT(dist(p, analytic_glabella()), 1.0) << p.x << " " << p.y << " " << p.z;

  const auto run = caps("model landmarks " + face_model().string() + " --json -q");
  ASSERT_EQ(run.code, 0) << run.out;
  const json j = json::parse(run.out);
  EXPECT_TRUE(j["written"].get<bool>());
  EXPECT_EQ(j["items"]["glabella"]["lps"], gl);
  const auto text = caps("model landmarks " + face_model().string() + " --no-write");
  ASSERT_EQ(text.code, 0) << text.out;
  EXPECT_NE(text.out.find("pogonion"), std::string::npos) << text.out;
}

// The face phantom (2 mm voxels) posed in the scanner (`caps phantom --pitch P --yaw Y`: turned
// about its axis point (2, 6, 0), yaw about S after pitch about L) and its model on a 256 x 128
// grid, without the tissue model: its model.json.
template <class... T>
std::string cat_args(const T&... parts) {
  std::ostringstream out;
  (out << ... << parts);
  return out.str();
}

json posed_face(double pitch, double yaw, const std::string& name, double roll = 0) {
  const fs::path ct = kTmp / (name + ".nii.gz"), dir = kTmp / name;
  fs::create_directories(kTmp);
  const auto ph = caps(cat_args("phantom --face --voxels 128,128,120 --spacing 2,2,2 --pitch ",
                                pitch, " --yaw ", yaw, " --roll ", roll, " -o ", ct.string(),
                                " --force -q"));
  EXPECT_EQ(ph.code, 0) << ph.out;
  const auto m = caps("model from-volume " + ct.string() + " -o " + dir.string() +
                      " --n-theta 256 --n-z 128 --no-tissue --force -q");
  EXPECT_EQ(m.code, 0) << m.out;
  return read_json(dir / "model.json");
}

// An upright head's point `q` (LPS) where the phantom puts it posed (`caps phantom --pitch
// --yaw`): turned about L through its axis point (2, 6, 0) by the pitch, then about S by the yaw.
V3 posed_point(const V3& q, double pitch_deg, double yaw_deg) {
  const double t = pitch_deg * M_PI / 180, y = yaw_deg * M_PI / 180;
  const double x = q.x - 2, yy = q.y - 6, z = q.z;
  const double y1 = std::cos(t) * yy - std::sin(t) * z, z1 = std::sin(t) * yy + std::cos(t) * z;
  return {2 + std::cos(y) * x - std::sin(y) * y1, 6 + std::sin(y) * x + std::cos(y) * y1, z1};
}

// The upright head's model.json, made once: the tilted and the leaning heads are both compared
// with it.
const json& upright_face() {
  static const json upright = posed_face(0, 0, "pose_upright");
  return upright;
}

TEST(CliLandmarks, AHeadTiltedInTheScannerIsPutUprightAndItsLandmarksFound) {
  // Issue 37: tilted 20 deg or more (as patients lie), the profile along the scanner's axis is
  // not a face's and the landmarks were all absent. from-volume now tilts the model's axis with
  // the head (docs/landmarks.md, "A head tilted or turned in the scanner"): each landmark lies
  // where the upright head's does, turned with the head (measured: within 0.91 mm, the tragia
  // 2.25 mm), and model.json's axis and its source notes say how it was tilted.
  const json& upright = upright_face();
  const json& axis0 = upright["axis"]["direction"];
  EXPECT_NEAR(axis0[2].get<double>(), 1.0, 1e-12) << "an upright head keeps the scanner's axis";
  EXPECT_FALSE(upright["source"].contains("pose"));
  struct Pose {
    double pitch, yaw, axis_deg;
  };
  // 30 deg forward: found with the axis tilted 20 and 30 deg, taken at 25; 20 deg forward and
  // turned 15 deg: found at 10, 20 and 30, taken at 20.
  for (const Pose& p : {Pose{30, 0, 25}, Pose{20, 15, 20}}) {
    const json m = posed_face(p.pitch, p.yaw, cat_args("pose_", p.pitch, "_", p.yaw));
    const double cos_tilt = m["axis"]["direction"][2].get<double>();
    EXPECT_NEAR(std::acos(cos_tilt) * 180 / M_PI, p.axis_deg, 1e-6) << "pitch " << p.pitch;
    EXPECT_NEAR(m["source"]["pose"]["pitch_deg"].get<double>(), p.axis_deg, 1e-9)
        << m["source"].dump();
    bool said = false;
    for (const auto& n : m["source"]["notes"])
      said = said || n.get<std::string>().find("tilted in the scanner") != std::string::npos;
    EXPECT_TRUE(said) << m["source"]["notes"].dump();
    for (const auto& [name, u] : upright["landmarks"]["items"].items()) {
      ASSERT_TRUE(u["found"].get<bool>()) << name;
      const auto& got = m["landmarks"]["items"][name];
      ASSERT_TRUE(got["found"].get<bool>()) << name << " pitch " << p.pitch << ": " << got["note"];
      const V3 want = posed_point(v3(u["lps"]), p.pitch, p.yaw);
      const double bound = name.rfind("tragion", 0) == 0 ? 3.0 : 1.5;
      EXPECT_LT(dist(v3(got["lps"]), want), bound) << name << " pitch " << p.pitch << " yaw " << p.yaw;
      // Issue 37's "thickness within 1 mm", the tragia too since their depth is read in the
      // hollow in front of the ear (measured: within 0.37 mm; the tragia 1.8 mm at 30 deg when it
      // was read at the ear's edge).
      EXPECT_NEAR(got["thickness_mm"].get<double>(), u["thickness_mm"].get<double>(), 1.0)
          << name << " pitch " << p.pitch << " yaw " << p.yaw;
    }
  }
}

TEST(CliLandmarks, AHeadLeaningToOneSideIsPutUprightAndItsLandmarksFound) {
  // Issue 37: a head leaning towards a shoulder (the vertex towards the patient's left by
  // `roll`). 10 deg: the left and right landmarks' heights give the roll; 25 deg: the skin is most
  // symmetric at the edge of the midline's search, the axis is turned 15 deg and refined
  // (docs/landmarks.md, "A head leaning to one side"). Each landmark lies where the upright
  // head's does, turned with the head (measured: within 0.61 mm and its thickness within 0.25
  // mm, the tragia 0.6 mm and their thickness 0.36 mm), and model.json's pose gives the roll.
  const json& upright = upright_face();
  for (const double roll : {10.0, 25.0}) {
    const json m = posed_face(0, 0, cat_args("lean_", roll), roll);
    ASSERT_TRUE(m["source"].contains("pose")) << "roll " << roll << ": " << m["source"].dump();
    EXPECT_NEAR(m["source"]["pose"]["roll_deg"].get<double>(), roll, 1.0);
    const double axis_deg = std::asin(m["axis"]["direction"][0].get<double>()) * 180 / M_PI;
    EXPECT_NEAR(axis_deg, roll, 1.0) << "the axis leans with the head";
    const double r = roll * M_PI / 180;
    for (const auto& [name, u] : upright["landmarks"]["items"].items()) {
      const auto& got = m["landmarks"]["items"][name];
      ASSERT_TRUE(got["found"].get<bool>()) << name << " roll " << roll << ": " << got["note"];
      // The upright point turned as the phantom leans the head: about P through (2, 6, 0).
      const V3 q = v3(u["lps"]);
      const V3 want{2 + std::cos(r) * (q.x - 2) + std::sin(r) * q.z, q.y,
                    -std::sin(r) * (q.x - 2) + std::cos(r) * q.z};
      const bool tragion = name.rfind("tragion", 0) == 0;
      EXPECT_LT(dist(v3(got["lps"]), want), tragion ? 3.0 : 1.0) << name << " roll " << roll;
      EXPECT_NEAR(got["thickness_mm"].get<double>(), u["thickness_mm"].get<double>(), 0.5)
          << name << " roll " << roll;
    }
  }
}

// Issue 37's own case: a CT head stored as unsigned 16-bit HU + 1024, big-endian raw slices
// under a .nhdr, the vertex's slice first, the head tilted forward in the scanner as patients
// lie. Read with the defaults it was called an MR and modelled with an assumed 6 mm of tissue,
// and its nose tip labelled the glabella. The posed phantom's NIfTI (int16 HU, its sform read
// here) is rewritten so: one file per slice, the slices from the top down, each value + 1024.
TEST(CliLandmarks, IssuesTiltedCtStoredUnsignedBigEndianVertexFirstIsReadAsTheCtItIs) {
  fs::create_directories(kTmp);
  const fs::path nii = kTmp / "tilt20.nii", raw = kTmp / "tilt20_slices";
  const auto ph = caps("phantom --face --voxels 128,128,120 --spacing 2,2,2 --pitch 20 -o " +
                       nii.string() + " --force -q");
  ASSERT_EQ(ph.code, 0) << ph.out;
  std::ifstream in(nii, std::ios::binary);
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  ASSERT_GE(bytes.size(), 352u);
  auto get = [&](std::size_t at, auto value) {
    std::memcpy(&value, bytes.data() + at, sizeof value);
    return value;
  };
  const int nx = get(42, std::int16_t{}), ny = get(44, std::int16_t{}),
            nz = get(46, std::int16_t{});
  ASSERT_EQ(get(70, std::int16_t{}), 4) << "the phantom is written as int16";
  const float slope = get(112, float{}), inter = get(116, float{});
  ASSERT_TRUE((slope == 0 || slope == 1) && inter == 0) << slope << " " << inter;
  ASSERT_GT(get(254, std::int16_t{}), 0) << "the phantom's sform";
  double srow[3][4];  // RAS from (i, j, k, 1)
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 4; ++c) srow[r][c] = get(280 + 16 * r + 4 * c, float{});
  const auto offset = static_cast<std::size_t>(get(108, float{}));
  const std::size_t n_slice = static_cast<std::size_t>(nx) * ny;
  ASSERT_EQ(bytes.size(), offset + 2 * n_slice * nz);
  fs::remove_all(raw);
  fs::create_directories(raw);
  for (int k = 0; k < nz; ++k) {  // file k holds slice nz - 1 - k: the vertex first
    std::string slice(2 * n_slice, '\0');
    for (std::size_t v = 0; v < n_slice; ++v) {
      const auto hu = get(offset + 2 * ((nz - 1 - k) * n_slice + v), std::int16_t{});
      ASSERT_GE(hu, -1024);
      const auto stored = static_cast<std::uint16_t>(hu + 1024);
      slice[2 * v] = static_cast<char>(stored >> 8);  // big-endian
      slice[2 * v + 1] = static_cast<char>(stored & 0xff);
    }
    std::ofstream(raw / cat_args("slice.", 1000 + k), std::ios::binary) << slice;
  }
  // LPS: L = -R, P = -A. The slice axis points down, from the top slice.
  auto lps = [&](int c, double s) {
    return cat_args("(", -srow[0][c] * s, ",", -srow[1][c] * s, ",", srow[2][c] * s, ")");
  };
  const double top[3] = {-(srow[0][3] + srow[0][2] * (nz - 1)),
                         -(srow[1][3] + srow[1][2] * (nz - 1)), srow[2][3] + srow[2][2] * (nz - 1)};
  std::ofstream(raw / "head.nhdr")
      << "NRRD0004\ntype: unsigned short\ndimension: 3\nspace: left-posterior-superior\n"
      << "sizes: " << nx << " " << ny << " " << nz << "\nspace directions: " << lps(0, 1) << " "
      << lps(1, 1) << " " << lps(2, -1) << "\nspace origin: (" << top[0] << "," << top[1] << ","
      << top[2] << ")\nendian: big\nencoding: raw\ndata file: slice.%d 1000 " << 1000 + nz - 1
      << " 1\n";
  const fs::path dir = kTmp / "tilt20_nhdr";
  const auto m = caps("model from-volume " + (raw / "head.nhdr").string() + " -o " + dir.string() +
                      " --n-theta 256 --n-z 128 --no-tissue --force -q");
  ASSERT_EQ(m.code, 0) << m.out;
  const json got = read_json(dir / "model.json");
  EXPECT_EQ(got["source"]["modality"], "CT") << got["source"].dump();
  ASSERT_TRUE(got["source"].contains("pose")) << got["source"].dump();
  EXPECT_NEAR(got["source"]["pose"]["pitch_deg"].get<double>(), 20, 1e-9);
  for (const auto& w : got["warnings"])
    EXPECT_EQ(w.get<std::string>().find("approximated"), std::string::npos) << w;
  // Each landmark where the upright head's lies turned 20 deg about L through (2, 6, 0), its
  // depth the upright head's (measured: within 0.43 mm, the tragia 0.16 mm).
  const json& upright = upright_face();
  for (const auto& [name, u] : upright["landmarks"]["items"].items()) {
    const auto& l = got["landmarks"]["items"][name];
    ASSERT_TRUE(l["found"].get<bool>()) << name << ": " << l["note"];
    const V3 want = posed_point(v3(u["lps"]), 20, 0);
    const bool tragion = name.rfind("tragion", 0) == 0;
    EXPECT_LT(dist(v3(l["lps"]), want), tragion ? 3.0 : 1.5) << name;
    EXPECT_NEAR(l["thickness_mm"].get<double>(), u["thickness_mm"].get<double>(), 1.0) << name;
  }
}

TEST(CliLandmarks, AnImplausibleDepthIsMarkedAndCarriedIntoPlansPlacedFromIt) {
  // The phantom's landmarks have plausible depths: none is marked but the nose's tip, whose 21 mm
  // are through the nose (cartilage in a head), not a layer over bone.
  const json m = read_json(face_model() / "model.json");
  for (const auto& [name, item] : m["landmarks"]["items"].items())
    EXPECT_EQ(item.contains("doubt"), name == "pronasale") << name << ": " << item.value("doubt", "");
  // A copy whose glabella reads 14 mm of soft tissue (the adult's is 5.5 +- 1.0 mm; on Cranium
  // the pronasale read 32 mm, the eye corners 32-39 mm, without a word): the landmark is marked,
  // and a plan placed from it carries the warning through plan new, plan check and simulate.
  const fs::path copy = kTmp / "face_doubt";
  fs::remove_all(copy);
  fs::copy(face_model(), copy, fs::copy_options::recursive);
  json edited = read_json(copy / "model.json");
  edited["landmarks"]["items"]["glabella"]["thickness_mm"] = 14.0;
  std::ofstream(copy / "model.json") << edited.dump(2);
  const auto listed = caps("plan new ellipse --model " + copy.string() + " --at glabella+0,15 "
                           "--orientation 90 -o " + (kTmp / "doubt.json").string() + " --force");
  ASSERT_EQ(listed.code, 0) << listed.out;
  EXPECT_NE(listed.out.find("placed from the glabella, whose measured soft tissue is implausible: "
                            "14 mm"), std::string::npos) << listed.out;
  const auto checked = caps("plan check " + (kTmp / "doubt.json").string() + " --model " + copy.string());
  EXPECT_NE(checked.out.find("implausible"), std::string::npos) << checked.out;
  const auto sim = caps("simulate -q --domain patch --material linear --model " + copy.string() +
                        " --plan " + (kTmp / "doubt.json").string() + " -o " +
                        (kTmp / "doubt_sim").string() + " --force");
  ASSERT_EQ(sim.code, 0) << sim.out;
  std::ifstream result(kTmp / "doubt_sim" / "result.json");
  const std::string text((std::istreambuf_iterator<char>(result)), std::istreambuf_iterator<char>());
  EXPECT_NE(text.find("whose measured soft tissue is implausible"), std::string::npos);
}

TEST(CliLandmarks, PlanAtGlabellaLandsOnTheAnalyticGlabella) {
  const fs::path plan = kTmp / "at_glabella.json";
  const auto run = caps("plan new ellipse --model " + face_model().string() +
                        " --at glabella+0,0 --orientation 90 -o " + plan.string() + " --force -q");
  ASSERT_EQ(run.code, 0) << run.out;
  const json p = read_json(plan);
  EXPECT_EQ(p["at"]["landmark"], "glabella");
  // The plan's centre is the landmark's (theta, z), and its skin point (caps model site at that
  // theta, z) is the analytic glabella within 1 mm.
  const json m = read_json(face_model() / "model.json");
  EXPECT_NEAR(p["frame"]["theta_deg"].get<double>(),
              m["landmarks"]["items"]["glabella"]["theta_deg"].get<double>(), 1e-6);
  EXPECT_NEAR(p["frame"]["z_mm"].get<double>(),
              m["landmarks"]["items"]["glabella"]["z_mm"].get<double>(), 1e-6);
  std::ostringstream at;
  at.precision(17);
  at << p["frame"]["theta_deg"].get<double>() << "," << p["frame"]["z_mm"].get<double>();
  const auto site = caps("model site " + face_model().string() + " --at=" + at.str() + " --json");
  ASSERT_EQ(site.code, 0) << site.out;
  const V3 centre = v3(json::parse(site.out)["lps"]);
  EXPECT_LT(dist(centre, analytic_glabella()), 1.0) << centre.x << " " << centre.y << " " << centre.z;

  // 15 mm to the left and 20 mm up: the centre moves to the patient's left (+x) and up (+z), 25 mm
  // along the skin (the chord is a little shorter).
  const fs::path moved = kTmp / "moved.json";
  ASSERT_EQ(caps("plan new ellipse --model " + face_model().string() +
                 " --at glabella+15,20 --orientation 90 -o " + moved.string() + " --force -q")
                .code,
            0);
  const json q = read_json(moved);
  EXPECT_EQ(q["at"]["left_mm"].get<double>(), 15.0);
  EXPECT_EQ(q["at"]["up_mm"].get<double>(), 20.0);
  EXPECT_GT(q["frame"]["theta_deg"].get<double>(), p["frame"]["theta_deg"].get<double>() + 5);
  EXPECT_NEAR(q["frame"]["z_mm"].get<double>() - p["frame"]["z_mm"].get<double>(), 20.0, 3.0);
}

TEST(CliLandmarks, APlanPlacedByThetaAndZIsSaidFromItsNearestLandmark) {
  // Placed from the glabella 12 mm left and 8 mm up, then placed again by the (theta, z) that
  // gave: the check finds the glabella nearest and the same offsets back (the inverse of the
  // walk on the skin), and the summary says it in words, without theta or z.
  const fs::path from = kTmp / "near_from.json", again = kTmp / "near_again.json";
  ASSERT_EQ(caps("plan new ellipse --model " + face_model().string() +
                 " --at glabella+12,8 --orientation 90 -o " + from.string() + " --force -q")
                .code,
            0);
  const json p = read_json(from);
  std::ostringstream at;
  at.precision(17);
  at << p["frame"]["theta_deg"].get<double>() << "," << p["frame"]["z_mm"].get<double>();
  const auto run = caps("plan new ellipse --model " + face_model().string() + " --at=" + at.str() +
                        " --orientation 90 -o " + again.string() + " --force");
  ASSERT_EQ(run.code, 0) << run.out;
  const json q = read_json(again);
  EXPECT_FALSE(q.contains("at") && q["at"].contains("landmark"));  // placed by theta, z
  ASSERT_TRUE(q["check"].contains("near")) << q["check"].dump();
  EXPECT_EQ(q["check"]["near"]["landmark"], "glabella");
  EXPECT_NEAR(q["check"]["near"]["left_mm"].get<double>(), 12.0, 0.1);
  EXPECT_NEAR(q["check"]["near"]["up_mm"].get<double>(), 8.0, 0.1);
  EXPECT_NE(run.out.find("centre 12 mm to the patient's left and 8 mm up from the glabella"),
            std::string::npos) << run.out;
  // Beside the right eye: the nearest landmark is that eye's outer corner, said in words.
  const json m = read_json(face_model() / "model.json");
  const json& ex = m["landmarks"]["items"]["exocanthion_right"];
  std::ostringstream eye;
  eye.precision(17);
  eye << ex["theta_deg"].get<double>() << "," << ex["z_mm"].get<double>() - 12;
  const auto below = caps("plan new ellipse --model " + face_model().string() + " --at=" + eye.str() +
                          " --orientation 90 --length 8 --width 3 -o " + again.string() + " --force");
  ASSERT_EQ(below.code, 0) << below.out;
  EXPECT_NE(below.out.find("down from the right outer eye corner (exocanthion)"), std::string::npos)
      << below.out;
}

TEST(CliLandmarks, AnAbsentOrUnknownLandmarkIsInvalidInput) {
  // The plain phantom has a nose but no brow: no nasion, no glabella.
  const fs::path ct = kTmp / "plain.nii.gz", model = kTmp / "plain";
  ASSERT_EQ(caps("phantom --voxels 96,96,90 --spacing 2.5,2.5,2.5 -o " + ct.string() +
                 " --force -q").code, 0);
  ASSERT_EQ(caps("model from-volume " + ct.string() + " -o " + model.string() +
                 " --n-theta 128 --n-z 64 --no-tissue --force -q").code, 0);
  const auto absent = caps("plan new ellipse --model " + model.string() +
                           " --at glabella+0,10 -o " + (kTmp / "x.json").string());
  EXPECT_EQ(absent.code, 2) << absent.out;
  EXPECT_NE(absent.out.find("has no glabella"), std::string::npos) << absent.out;
  const auto unknown = caps("plan new ellipse --model " + model.string() +
                            " --at forehead+0,10 -o " + (kTmp / "x.json").string());
  EXPECT_EQ(unknown.code, 2) << unknown.out;
  EXPECT_NE(unknown.out.find("not a landmark"), std::string::npos) << unknown.out;
  const auto bad = caps("plan new ellipse --model " + model.string() +
                        " --at pronasale+a,b -o " + (kTmp / "x.json").string());
  EXPECT_EQ(bad.code, 2) << bad.out;
  // The theta,z form still works.
  EXPECT_EQ(caps("plan new ellipse --model " + model.string() + " --at 0,60 -o " +
                 (kTmp / "y.json").string() + " --force -q").code, 0);
}

TEST(CliLandmarks, ASiteOrAWoundOverImplausibleTissueIsMarked) {
  // caps model site at the phantom's nose tip (21 mm through its nose to the bone: no layer a
  // flap is raised in) marks it; on the forehead it says nothing. A closure whose wound's centre
  // lies on the nose tip carries the same warning into result.json.
  const auto tip = caps("model site " + face_model().string() + " --at pronasale --json");
  ASSERT_EQ(tip.code, 0) << tip.out;
  const json t = json::parse(tip.out.substr(tip.out.find('{')));
  EXPECT_GT(t["thickness_mm"].get<double>(), 20.0);  // surface/landmarks.hpp, kMaxFacialTissueMm
  EXPECT_NE(t.value("doubt", "").find("deeper than any facial landmark's"), std::string::npos) << tip.out;
  const auto brow = caps("model site " + face_model().string() + " --at glabella+0,15 --json");
  ASSERT_EQ(brow.code, 0) << brow.out;
  EXPECT_FALSE(json::parse(brow.out.substr(brow.out.find('{'))).contains("doubt")) << brow.out;

  const fs::path plan = kTmp / "on_tip.json";
  const auto placed = caps("plan new ellipse --model " + face_model().string() +
                           " --at pronasale --length 8 --width 3 -o " + plan.string() + " --force -q");
  ASSERT_EQ(placed.code, 0) << placed.out;
  const auto sim = caps("simulate -q --domain patch --material linear --model " +
                        face_model().string() + " --plan " + plan.string() + " -o " +
                        (kTmp / "on_tip_sim").string() + " --force");
  ASSERT_EQ(sim.code, 0) << sim.out;
  const json r = read_json(kTmp / "on_tip_sim" / "result.json");
  bool said = false;
  for (const auto& w : r["warnings"]) said |= w.get<std::string>().find("under the wound's centre") != std::string::npos;
  EXPECT_TRUE(said) << r["warnings"].dump();
}

// Dental metal at the chin (issue 37): the pogonion in its band of unmeasured cells is absent,
// and its note says that metal was found and where the band lies (the detector alone would say
// only that no chin prominence was measured, as where the CT ends above the chin); the
// landmarks away from the band keep notes without it.
TEST(CliLandmarks, ALandmarkLostToMetalSaysSo) {
  const fs::path dir = kTmp / "metal";
  fs::remove_all(dir);
  fs::create_directories(dir);
  const auto ph = caps("phantom --face --metal --metal-z -68 --voxels 170,170,160 "
                       "--spacing 1.5,1.5,1.5 -o " + (dir / "ct.nii.gz").string() + " -q");
  ASSERT_EQ(ph.code, 0) << ph.out;
  const auto m = caps("model from-volume " + (dir / "ct.nii.gz").string() + " -o " +
                      (dir / "model").string() + " --no-tissue --n-theta 128 --n-z 64");
  ASSERT_EQ(m.code, 0) << m.out;
  const json j = read_json(dir / "model" / "model.json");
  const json& metal = j.at("segmentation").at("metal");
  ASSERT_TRUE(metal.at("found").get<bool>());
  const json& items = j.at("landmarks").at("items");
  const json& pogonion = items.at("pogonion");
  EXPECT_FALSE(pogonion.at("found").get<bool>());
  const std::string note = pogonion.at("note");
  EXPECT_NE(note.find("metal was found in this CT"), std::string::npos) << note;
  const double z0 = metal.at("cells").at("z_mm")[0], z1 = metal.at("cells").at("z_mm")[1];
  std::ostringstream band;
  band << "from z " << std::round(z0 * 10) / 10 << " to " << std::round(z1 * 10) / 10 << " mm";
  EXPECT_NE(note.find(band.str()), std::string::npos) << note;
  // The CLI says it where the user reads it.
  EXPECT_NE(m.out.find("landmark pogonion absent"), std::string::npos) << m.out;
  EXPECT_NE(m.out.find("metal was found"), std::string::npos) << m.out;
  for (const auto& [name, item] : items.items())
    if (item.at("found").get<bool>())
      EXPECT_EQ(item.at("note").get<std::string>().find("metal"), std::string::npos) << name;
}
