// NIfTI-1 writing: int16 for whole-number data, else float32; one file (.nii) or gzip (.nii.gz), qform and sform both set from the
// LPS geometry converted to RAS (negate the first two rows). Written by hand with zlib rather than
// through nifti_image_write so that the temporary name chosen by write_file_atomic is honoured.

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>

#include "caps/core/atomic_output.hpp"
#include "caps/core/error.hpp"
#include "caps/volume/read_volume.hpp"
#include "volume_io_detail.hpp"

#include <nifti2_io.h>
#include <zlib.h>

namespace fs = std::filesystem;

namespace caps {

void write_nifti(const Volume& v, const fs::path& path) {
  const std::string name = detail::to_lower(path.filename().string());
  const bool gz = name.size() > 7 && name.compare(name.size() - 7, 7, ".nii.gz") == 0;
  const bool nii = name.size() > 4 && name.compare(name.size() - 4, 4, ".nii") == 0;
  if (!gz && !nii)
    throw InvalidInput(cat(path.string(), ": a NIfTI output must end in .nii or .nii.gz"));
  const auto& g = v.geom;
  if (g.dims.minCoeff() <= 0 || v.data.size() != g.n_voxels())
    throw InvalidInput(cat(path.string(), ": cannot write ", v.source, ": dims (",
                           g.dims.transpose(), ") do not match its ", v.data.size(), " values"));

  nifti_1_header h;
  std::memset(&h, 0, sizeof h);
  h.sizeof_hdr = 348;
  h.dim[0] = 3;
  for (int a = 0; a < 3; ++a) {
    if (g.dims[a] > 32767)
      throw InvalidInput(cat(path.string(), ": dimension ", g.dims[a],
                             " does not fit NIfTI-1 (max 32767)"));
    h.dim[a + 1] = static_cast<short>(g.dims[a]);
  }
  for (int a = 4; a < 8; ++a) h.dim[a] = 1;
  // Integer values that fit (CT in HU, label maps) are stored as int16, as scanners store them;
  // anything else as float32.
  const bool as_int16 = std::all_of(v.data.begin(), v.data.end(), [](float x) {
    return x == std::nearbyint(x) && x >= -32768.0f && x <= 32767.0f;
  });
  std::vector<std::int16_t> int16_data;
  if (as_int16) {
    int16_data.resize(v.data.size());
    for (std::size_t i = 0; i < v.data.size(); ++i) int16_data[i] = static_cast<std::int16_t>(v.data[i]);
  }
  h.datatype = as_int16 ? DT_INT16 : DT_FLOAT32;
  h.bitpix = as_int16 ? 16 : 32;
  h.vox_offset = 352;
  h.scl_slope = 1.0f;
  h.scl_inter = 0.0f;
  h.xyzt_units = NIFTI_UNITS_MM | NIFTI_UNITS_SEC;
  std::memcpy(h.magic, "n+1\0", 4);
  std::snprintf(h.descrip, sizeof h.descrip, "caps %s", v.format.c_str());

  // LPS affine -> RAS.
  const Eigen::Matrix3d flip = Eigen::Vector3d(-1, -1, 1).asDiagonal();
  const Eigen::Matrix3d M = flip * g.direction * g.spacing_mm.asDiagonal();
  const Eigen::Vector3d t = flip * g.origin_lps;
  nifti_dmat44 R;
  std::memset(&R, 0, sizeof R);
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) R.m[r][c] = M(r, c);
    R.m[r][3] = t[r];
  }
  R.m[3][3] = 1.0;
  double qb, qc, qd, qx, qy, qz, dx, dy, dz, qfac;
  nifti_dmat44_to_quatern(R, &qb, &qc, &qd, &qx, &qy, &qz, &dx, &dy, &dz, &qfac);
  h.pixdim[0] = static_cast<float>(qfac);
  for (int a = 0; a < 3; ++a) h.pixdim[a + 1] = static_cast<float>(g.spacing_mm[a]);
  h.qform_code = NIFTI_XFORM_SCANNER_ANAT;
  h.sform_code = NIFTI_XFORM_SCANNER_ANAT;
  h.quatern_b = static_cast<float>(qb);
  h.quatern_c = static_cast<float>(qc);
  h.quatern_d = static_cast<float>(qd);
  h.qoffset_x = static_cast<float>(qx);
  h.qoffset_y = static_cast<float>(qy);
  h.qoffset_z = static_cast<float>(qz);
  for (int c = 0; c < 4; ++c) {
    h.srow_x[c] = static_cast<float>(R.m[0][c]);
    h.srow_y[c] = static_cast<float>(R.m[1][c]);
    h.srow_z[c] = static_cast<float>(R.m[2][c]);
  }
  float lo = 0, hi = 0;
  if (!v.data.empty()) {
    lo = hi = v.data[0];
    for (float x : v.data) lo = std::min(lo, x), hi = std::max(hi, x);
  }
  h.cal_min = lo;
  h.cal_max = hi;

  const char extension[4] = {0, 0, 0, 0};
  const std::size_t n_bytes = v.data.size() * (as_int16 ? sizeof(std::int16_t) : sizeof(float));
  const void* payload = as_int16 ? static_cast<const void*>(int16_data.data())
                                 : static_cast<const void*>(v.data.data());
  write_file_atomic(path, [&](const fs::path& tmp) {
    const std::string tname = tmp.string();
    bool ok = true;
    if (gz) {
      gzFile f = gzopen(tname.c_str(), "wb6");
      if (!f) throw IoError(cat(path.string(), ": cannot create the file"));
      ok = gzwrite(f, &h, sizeof h) == static_cast<int>(sizeof h) &&
           gzwrite(f, extension, 4) == 4;
      // gzwrite takes an unsigned length: write in chunks below 1 GB.
      const char* p = static_cast<const char*>(payload);
      for (std::size_t off = 0; ok && off < n_bytes;) {
        const unsigned len = static_cast<unsigned>(std::min<std::size_t>(n_bytes - off, 1u << 30));
        ok = gzwrite(f, p + off, len) == static_cast<int>(len);
        off += len;
      }
      ok = (gzclose(f) == Z_OK) && ok;
    } else {
      std::FILE* f = std::fopen(tname.c_str(), "wb");
      if (!f) throw IoError(cat(path.string(), ": cannot create the file"));
      ok = std::fwrite(&h, sizeof h, 1, f) == 1 && std::fwrite(extension, 4, 1, f) == 1 &&
           (n_bytes == 0 || std::fwrite(payload, n_bytes, 1, f) == 1);
      ok = (std::fclose(f) == 0) && ok;
    }
    if (!ok) throw IoError(cat(path.string(), ": write failed (disk full?)"));
  });
}

}  // namespace caps
