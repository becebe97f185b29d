// Writing and reading clouds as PCD, PLY (through PCL's own writers, so PCL, CloudCompare and
// Open3D read them) and DRC (Draco). The format follows the file extension.
#pragma once

#include <string>

#include "absl/status/status.h"
#include "cloudcast/core/draco_codec.h"
#include "cloudcast/core/point.h"

namespace cloudcast {

// The formats:
//   .pcd  PCL binary PCD, fields x y z rgb (rgb is PCL's packed float word, alpha included).
//         Organized clouds keep width, height and their NaN points; is_dense says whether any
//         point is NaN.
//   .ply  binary little-endian PLY, vertex x y z (float) + red green blue (uchar), finite points
//         only (PLY has no invalid vertices), no PCL camera element.
//   .drc  Draco point cloud with POSITION and COLOR (EncodeDraco with `draco`; NaN points dropped,
//         positions quantized).
// An empty cloud gives a valid file without points (which PCL's and Open3D's readers refuse, but
// LoadCloud reads). The extension picks the format, case-insensitively. Errors name the file and
// the reason; an unknown extension lists the supported ones.
absl::Status SaveCloud(const std::string& path, const PointCloud& cloud,
                       const DracoOptions& draco = DracoOptions{});

// Reads .pcd, .ply or .drc into our layout, from our files or other tools' (PCL, Open3D,
// CloudCompare, draco_encoder). Organized PCD/PLY stay organized, NaN points with colour 0;
// otherwise only the finite points are kept. Files without colour give white points; colour
// without alpha (PLY, DRC) gives alpha 255. On error `out` is unspecified.
absl::Status LoadCloud(const std::string& path, PointCloud* out);

// OK when the extension of `path` is one SaveCloud / LoadCloud know; otherwise an error naming
// the path and listing SupportedCloudExtensions(). Lets tools reject a bad name before working.
absl::Status CheckCloudPath(const std::string& path);
// ".pcd, .ply, .drc"
const char* SupportedCloudExtensions();

}  // namespace cloudcast
