// Writes the seed corpora of the fuzz targets into <dir>/<target>/ from caps' own writers and a
// small phantom CT: every reader starts from files that it accepts, so that the fuzzer mutates
// its way into the deep paths rather than the first magic-number check.
//
//   fuzz_seeds <dir>

#include <gdcmAttribute.h>
#include <gdcmImage.h>
#include <gdcmImageChangeTransferSyntax.h>
#include <gdcmImageWriter.h>
#include <gdcmTrace.h>

#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include "caps/fem/box.hpp"
#include "caps/fem/mesh_io.hpp"
#include "caps/image/image_io.hpp"
#include "caps/plan/plan_io.hpp"
#include "caps/plan/procedures.hpp"
#include "caps/volume/mesh_io.hpp"
#include "caps/volume/model_dir.hpp"
#include "caps/volume/phantom.hpp"
#include "caps/volume/read_volume.hpp"
#include "fuzz_input.hpp"

namespace fs = std::filesystem;

namespace {

fs::path root;

std::string slurp(const fs::path& p) {
  std::ifstream in(p, std::ios::binary);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

void seed(const std::string& target, const std::string& name, const std::string& bytes) {
  fs::create_directories(root / target);
  std::ofstream(root / target / name, std::ios::binary) << bytes;
}

std::string join(const std::string& a, const std::string& b) {
  return a + std::string(caps_fuzz::kSeparator) + b;
}

// A phantom of n^3 voxels of 10 mm (the middle of the head).
caps::Volume small_phantom(int n) {
  caps::PhantomOptions o;
  o.dims = Eigen::Vector3i(n, n, n);
  o.spacing_mm = Eigen::Vector3d::Constant(10.0);
  o.head_holder = false;
  return caps::make_phantom(o);
}

std::string int16_bytes(const caps::Volume& v) {
  std::string raw(v.data.size() * 2, '\0');
  for (std::size_t i = 0; i < v.data.size(); ++i) {
    const auto s = static_cast<std::int16_t>(v.data[i]);
    std::memcpy(&raw[2 * i], &s, 2);
  }
  return raw;
}

void volume_seeds(const fs::path& tmp) {
  const caps::Volume v = small_phantom(8);
  const std::string raw = int16_bytes(v);
  // NIfTI, plain and gzip, from caps' writer.
  caps::write_nifti(v, tmp / "p.nii");
  caps::write_nifti(v, tmp / "p.nii.gz");
  seed("fuzz_nifti", "phantom.nii", slurp(tmp / "p.nii"));
  seed("fuzz_nifti", "phantom.nii.gz", slurp(tmp / "p.nii.gz"));
  // NRRD, attached and detached (raw, ascii).
  const std::string nrrd_head =
      "NRRD0004\ntype: short\ndimension: 3\nsizes: 8 8 8\nspace: left-posterior-superior\n"
      "space directions: (10,0,0) (0,10,0) (0,0,10)\nspace origin: (-100,-100,-100)\n"
      "endian: little\n";
  seed("fuzz_nrrd", "raw.nrrd", nrrd_head + "encoding: raw\n\n" + raw);
  seed("fuzz_nrrd", "detached.nhdr", join(nrrd_head + "encoding: raw\ndata file: data.raw\n", raw));
  std::string ascii;
  for (const float x : v.data) ascii += std::to_string(static_cast<int>(x)) + " ";
  seed("fuzz_nrrd", "ascii.nrrd", nrrd_head + "encoding: ascii\n\n" + ascii);
  // MetaImage, attached and detached.
  const std::string mha_head =
      "ObjectType = Image\nNDims = 3\nBinaryData = True\nBinaryDataByteOrderMSB = False\n"
      "Offset = -100 -100 -100\nTransformMatrix = 1 0 0 0 1 0 0 0 1\nElementSpacing = 10 10 10\n"
      "DimSize = 8 8 8\nElementType = MET_SHORT\n";
  seed("fuzz_metaimage", "local.mha", mha_head + "ElementDataFile = LOCAL\n" + raw);
  seed("fuzz_metaimage", "detached.mhd", join(mha_head + "ElementDataFile = data.raw\n", raw));
  seed("fuzz_metaimage", "list.mhd",
       join(mha_head + "ElementDataFile = data.raw%d 1 1 1\n", raw));
  // DICOM through GDCM's writer: two 8x8 slices of the phantom as one series, one of them
  // compressed (RLE, JPEG lossless: the codecs' paths), and the whole phantom as one multi-frame
  // file of 8 frames.
  gdcm::Trace::SetWarning(false);
  auto dicom = [&](int k, int frames, const gdcm::TransferSyntax& ts) {
    gdcm::ImageWriter w;
    gdcm::Image& im = w.GetImage();
    im.SetNumberOfDimensions(frames > 1 ? 3 : 2);
    im.SetDimension(0, 8);
    im.SetDimension(1, 8);
    if (frames > 1) im.SetDimension(2, static_cast<unsigned>(frames));
    im.SetPhotometricInterpretation(gdcm::PhotometricInterpretation::MONOCHROME2);
    im.SetPixelFormat(gdcm::PixelFormat(gdcm::PixelFormat::INT16));
    for (int a = 0; a < 3; ++a) im.SetSpacing(a, 10);
    im.SetOrigin(0, -100);
    im.SetOrigin(1, -100);
    im.SetOrigin(2, -100 + 10 * k);
    im.SetIntercept(0);
    im.SetSlope(1);
    const std::string pixels_bytes = raw.substr(static_cast<std::size_t>(k) * 128, 128 * frames);
    gdcm::DataElement pixels(gdcm::Tag(0x7fe0, 0x0010));
    pixels.SetByteValue(pixels_bytes.data(), static_cast<std::uint32_t>(pixels_bytes.size()));
    im.SetDataElement(pixels);
    if (ts != gdcm::TransferSyntax::ExplicitVRLittleEndian) {
      gdcm::ImageChangeTransferSyntax change;
      change.SetTransferSyntax(ts);
      change.SetInput(im);
      if (!change.Change()) throw std::runtime_error("GDCM could not compress the DICOM seed");
      w.SetImage(change.GetOutput());
    }
    gdcm::DataSet& ds = w.GetFile().GetDataSet();
    gdcm::Attribute<0x0008, 0x0060> modality = {"CT"};
    ds.Replace(modality.GetAsDataElement());
    gdcm::Attribute<0x0020, 0x000e> series = {"1.2.826.0.1.3680043.2.1125.1.1"};
    ds.Replace(series.GetAsDataElement());
    gdcm::Attribute<0x0020, 0x0013> number = {k + 1};
    ds.Replace(number.GetAsDataElement());
    const fs::path p = tmp / ("dicom" + std::to_string(k) + "-" + std::to_string(frames) + ".dcm");
    w.SetFileName(p.string().c_str());
    if (!w.Write()) throw std::runtime_error("GDCM could not write the DICOM seed");
    return slurp(p);
  };
  const auto native = gdcm::TransferSyntax::ExplicitVRLittleEndian;
  const std::string slice0 = dicom(0, 1, native), slice1 = dicom(1, 1, native);
  seed("fuzz_dicom", "one_slice.dcm", slice0);
  seed("fuzz_dicom", "two_slices", join(slice0, slice1));
  seed("fuzz_dicom", "rle_slices", join(dicom(0, 1, gdcm::TransferSyntax::RLELossless), slice1));
  seed("fuzz_dicom", "jpeg_lossless.dcm", dicom(0, 1, gdcm::TransferSyntax::JPEGLosslessProcess14_1));
  seed("fuzz_dicom", "multi_frame.dcm", dicom(0, 8, native));
  // InVesalius: a tar (plain and gzip) of main.plist and the raw volume, through tar(1).
  const fs::path inv = tmp / "inv3";
  fs::create_directories(inv);
  std::ofstream(inv / "main.plist")
      << "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<plist version=\"1.0\">\n<dict>\n"
         "<key>matrix</key><dict><key>filename</key><string>matrix.dat</string>"
         "<key>shape</key><array><integer>8</integer><integer>8</integer><integer>8</integer>"
         "</array><key>dtype</key><string>int16</string></dict>\n<key>spacing</key><array>"
         "<real>10.0</real><real>10.0</real><real>10.0</real></array>\n<key>modality</key>"
         "<string>CT</string>\n</dict>\n</plist>\n";
  std::ofstream(inv / "matrix.dat", std::ios::binary) << raw;
  const std::string tar = "tar -C " + inv.string() + " --format=gnu -cf " + (tmp / "p.tar").string() +
                          " main.plist matrix.dat";
  if (std::system(tar.c_str()) != 0 ||
      std::system(("gzip -9 -n -k -f " + (tmp / "p.tar").string()).c_str()) != 0)
    throw std::runtime_error("tar/gzip failed writing the .inv3 seed");
  seed("fuzz_inv3", "phantom.inv3", slurp(tmp / "p.tar.gz"));
  seed("fuzz_inv3", "phantom_plain_tar.inv3", slurp(tmp / "p.tar"));
}

void scan_seeds(const fs::path& tmp) {
  // A small closed mesh: a tetrahedron.
  caps::TriMesh m;
  m.V.resize(4, 3);
  m.V << 0, 0, 0, 10, 0, 0, 0, 10, 0, 0, 0, 10;
  m.F.resize(4, 3);
  m.F << 0, 2, 1, 0, 1, 3, 0, 3, 2, 1, 2, 3;
  caps::write_ply(m, tmp / "t.ply");
  seed("fuzz_ply", "binary.ply", slurp(tmp / "t.ply"));
  seed("fuzz_ply", "ascii.ply",
       "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n"
       "property float z\nproperty uchar red\nproperty uchar green\nproperty uchar blue\n"
       "element face 4\nproperty list uchar int vertex_indices\nend_header\n0 0 0 255 0 0\n"
       "10 0 0 0 255 0\n0 10 0 0 0 255\n0 0 10 9 9 9\n3 0 2 1\n3 0 1 3\n4 0 3 2 1\n3 1 2 3\n");
  seed("fuzz_obj", "tet.obj",
       "# tetrahedron\nmtllib none.mtl\nv 0 0 0\nv 10 0 0\nv 0 10 0\nv 0 0 10\nvt 0 0\nvt 1 0\n"
       "vt 0 1\nvn 0 0 1\nusemtl skin\nf 1/1/1 3/3/1 2/2/1\nf 1/1 2/2 4/3\nf 1//1 4//1 3//1\n"
       "f -3 -2 -1 -4\n");
  const std::string vtk_head = "# vtk DataFile Version 3.0\ntet\nASCII\nDATASET POLYDATA\n";
  seed("fuzz_vtk", "tet.vtk",
       vtk_head + "POINTS 4 float\n0 0 0 10 0 0 0 10 0 0 0 10\nPOLYGONS 4 16\n3 0 2 1\n3 0 1 3\n"
                  "3 0 3 2\n3 1 2 3\nPOINT_DATA 4\nTEXTURE_COORDINATES tc 2 float\n0 0 1 0 0 1 1 1\n");
  seed("fuzz_vtk", "strips.vtk",
       vtk_head + "POINTS 4 float\n0 0 0 10 0 0 0 10 0 0 0 10\nTRIANGLE_STRIPS 1 5\n4 0 1 2 3\n");
  // glTF: one triangle with its buffer in a data: URI; the same as a .glb.
  const std::string b64 = "AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAAAAABAAIA";
  const std::string gltf =
      "{\"asset\": {\"version\": \"2.0\"}, \"scene\": 0, \"scenes\": [{\"nodes\": [0]}], "
      "\"nodes\": [{\"mesh\": 0, \"children\": [1]}, {\"mesh\": 0, \"scale\": [2, 2, 2]}], "
      "\"meshes\": [{\"primitives\": [{\"attributes\": {\"POSITION\": 0}, \"indices\": 1}]}], "
      "\"accessors\": [{\"bufferView\": 0, \"componentType\": 5126, \"count\": 3, \"type\": "
      "\"VEC3\", \"min\": [0, 0, 0], \"max\": [1, 1, 0]}, {\"bufferView\": 1, \"componentType\": "
      "5123, \"count\": 3, \"type\": \"SCALAR\"}], \"bufferViews\": [{\"buffer\": 0, "
      "\"byteLength\": 36}, {\"buffer\": 0, \"byteOffset\": 36, \"byteLength\": 6}], "
      "\"buffers\": [{\"byteLength\": 42, \"uri\": \"data:application/octet-stream;base64," +
      b64 + "\"}]}";
  seed("fuzz_gltf", "triangle.gltf", gltf);
  {
    std::string json =
        "{\"asset\": {\"version\": \"2.0\"}, \"scene\": 0, \"scenes\": [{\"nodes\": [0]}], "
        "\"nodes\": [{\"mesh\": 0}], \"meshes\": [{\"primitives\": [{\"attributes\": "
        "{\"POSITION\": 0}, \"indices\": 1}]}], \"accessors\": [{\"bufferView\": 0, "
        "\"componentType\": 5126, \"count\": 3, \"type\": \"VEC3\", \"min\": [0, 0, 0], "
        "\"max\": [1, 1, 0]}, {\"bufferView\": 1, \"componentType\": 5123, \"count\": 3, "
        "\"type\": \"SCALAR\"}], \"bufferViews\": [{\"buffer\": 0, \"byteLength\": 36}, "
        "{\"buffer\": 0, \"byteOffset\": 36, \"byteLength\": 6}], \"buffers\": "
        "[{\"byteLength\": 42}]}";
    while (json.size() % 4) json += ' ';
    std::string bin(44, '\0');
    const float xyz[9] = {0, 0, 0, 1, 0, 0, 0, 1, 0};
    const std::uint16_t idx[3] = {0, 1, 2};
    std::memcpy(&bin[0], xyz, 36);
    std::memcpy(&bin[36], idx, 6);
    auto u32 = [](std::uint32_t x) { return std::string(reinterpret_cast<const char*>(&x), 4); };
    const std::string glb = "glTF" + u32(2) + u32(static_cast<std::uint32_t>(12 + 8 + json.size() + 8 + bin.size())) +
                            u32(static_cast<std::uint32_t>(json.size())) + "JSON" + json +
                            u32(static_cast<std::uint32_t>(bin.size())) + std::string("BIN\0", 4) + bin;
    seed("fuzz_gltf", "triangle.glb", glb);
  }
  // Cyberware-style range image: 16-bit grey 8 x 4 with a void sample, and its sidecar.
  caps::GreyImage range;
  range.width = 8;
  range.height = 4;
  range.value.assign(32, 9000);
  range.value[5] = 0;
  caps::write_grey16_png(tmp / "range.png", range);
  const std::string sidecar =
      "{\"range\": \"range.png\", \"r_scale_mm\": 0.01, \"r_offset_mm\": 0, \"z_scale_mm\": 2, "
      "\"theta_span_deg\": 360, \"theta_axis\": \"columns\", \"theta_reverse\": false, "
      "\"top_first\": true, \"void_value\": 0, \"top_z_mm\": 40}";
  seed("fuzz_cylindrical_scan", "range", join(sidecar, slurp(tmp / "range.png")));
}

void json_seeds(const fs::path& tmp) {
  // Plans and procedure files: every template of the library laid out in a frame of 1 mm per
  // degree, so that no model is needed.
  for (const auto& info : caps::plan::procedure_library()) {
    const caps::plan::LocalProcedure proc = caps::plan::layout_procedure(info.name, {});
    caps::plan::Plan plan;
    plan.model = "model";
    plan.procedure = proc.name;
    plan.parameters = proc.parameters;
    plan.frame.theta_deg = 10;
    plan.frame.z_mm = 60;
    for (const auto& xy : proc.points_mm) {
      const Eigen::Vector2d tz = plan.frame.to_theta_z(xy);
      plan.points.push_back({tz.x(), tz.y(), {0, 0, 0}});
    }
    plan.paths = proc.paths;
    plan.excisions = proc.excisions;
    plan.sutures = proc.sutures;
    plan.flaps = proc.flaps;
    seed("fuzz_plan_json", info.name + ".json", caps::plan::plan_to_json(plan));
    seed("fuzz_plan_json", info.name + ".procedure.json", caps::plan::procedure_to_json(proc));
  }
  // model.json of a default model.
  caps::ModelInfo info;
  info.source_json = R"({"kind": "volume", "path": "ct.nii.gz", "format": "NIfTI-1"})";
  info.warnings = {"a warning"};
  info.content_hash = "0123456789abcdef";
  seed("fuzz_model_json", "model.json", caps::model_json_text(info));
  // A mesh directory: a box of 2 x 1 x 1 Hex20, and of wedges with a sutured slot.
  for (const bool slot : {false, true}) {
    caps::fem::BoxOptions o;
    o.cells = slot ? Eigen::Vector3i(3, 3, 1) : Eigen::Vector3i(2, 1, 1);
    o.slot = slot;
    o.wedges = slot;
    const fs::path d = tmp / (slot ? "slot_mesh" : "box_mesh");
    fs::create_directories(d);
    caps::fem::write_mesh_dir(caps::fem::make_box_mesh(o), d);
    seed("fuzz_mesh_json", d.filename().string(), join(slurp(d / "mesh.json"), slurp(d / "mesh.vtu")));
  }
  // Requests (fuzz_request.cpp: the first byte picks the type), as a front end sends them.
  const std::string requests[8] = {
      R"({"procedure": "z-plasty", "model": "m", "at": "0,60", "orientation": 30,
          "parameters": {"limb_mm": 20, "angle_deg": 60}, "output": "p.json", "force": true})",
      R"({"plan": "p.json", "model": "m"})",
      R"({"model": "m", "plan": "p.json", "output": "r", "suture_spacing": 3, "render": true})",
      R"({"model": "m", "plan": "p.json", "output": "mesh", "mesh_size": 2.5})",
      R"({"scan": "s.ply", "output": "m", "thickness": 6})",
      R"({"input": "ct.nii.gz", "output": "m", "n_theta": 96, "n_z": 48})",
      R"({"result": "r", "output": "a.png", "view": "front"})",
      R"({"plan": "p.json", "output": "p.png"})"};
  for (int i = 0; i < 8; ++i)
    seed("fuzz_request", "request" + std::to_string(i), std::string(1, static_cast<char>(i)) + requests[i]);
  // The server's connections (fuzz_server.cpp: {HOST} and {TOKEN} become the server's), as the
  // page and a hostile page send them.
  const auto post = [](const std::string& path, const std::string& body, const std::string& more) {
    return "POST " + path + " HTTP/1.1\r\nHost: {HOST}\r\nX-Caps-Token: {TOKEN}\r\n" + more +
           "Content-Type: application/json\r\nContent-Length: " + std::to_string(body.size()) +
           "\r\n\r\n" + body;
  };
  const std::string plan_new =
      R"({"procedure": "v-y-advancement", "at": "0,60", "orientation": 90,)"
      R"( "parameters": {"length": 12, "advance": 3}})";
  const std::string server_requests[] = {
      "GET / HTTP/1.1\r\nHost: {HOST}\r\n\r\n",
      "GET /api/model HTTP/1.1\r\nHost: {HOST}\r\nX-Caps-Token: {TOKEN}\r\n\r\n"
      "GET /api/progress HTTP/1.1\r\nHost: {HOST}\r\nCookie: a=b; caps_token_8765={TOKEN}\r\n\r\n",
      "GET /api/model/skin.ply HTTP/1.1\r\nHost: evil.example:8765\r\n\r\n",
      "GET /api/model/%C0%AFmodel.json HTTP/1.1\r\nHost: {HOST}\r\nX-Caps-Token: {TOKEN}\r\n\r\n",
      "GET /api/results/1/../../x HTTP/1.1\r\nHost: {HOST}\r\nX-Caps-Token: {TOKEN}\r\n\r\n",
      post("/api/plan/new", plan_new, "Origin: http://{HOST}\r\n"),
      post("/api/plan/new", plan_new, "Origin: http://evil.example\r\n"),
      post("/api/plan/check?name=p.json", R"({"version": 1, "incisions": [[0, 1]]})", ""),
      post("/api/plan/lines", "[[[[[[[[[[[[[[[[]]]]]]]]]]]]]]]]", ""),
      post("/api/simulate", R"({"plan": {}, "options": {"mesh_size": 0}})", ""),
      post("/api/chart", R"({"at": "x,y"})", ""),
      post("/api/plan/new", "{\"procedure\": \"\xc0\xaf\"}", ""),
      "POST /api/plan/new HTTP/1.1\r\nHost: {HOST}\r\nX-Caps-Token: {TOKEN}\r\n"
      "Transfer-Encoding: chunked\r\n\r\n4\r\n{\"a\"\r\n3\r\n: 1\r\n1\r\n}\r\n0\r\n\r\n",
      "DELETE /api/simulate HTTP/1.1\r\nHost: {HOST}\r\nX-Caps-Token: {TOKEN}\r\n\r\n"};
  int n = 0;
  for (const std::string& r : server_requests) seed("fuzz_server", "request" + std::to_string(n++), r);
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::cerr << "usage: fuzz_seeds <dir>\n";
    return 2;
  }
  try {
    root = argv[1];
    const fs::path tmp = root / "tmp";
    fs::create_directories(tmp);
    volume_seeds(tmp);
    scan_seeds(tmp);
    json_seeds(tmp);
    fs::remove_all(tmp);
  } catch (const std::exception& e) {
    std::cerr << "fuzz_seeds: " << e.what() << "\n";
    return 1;
  }
  return 0;
}
