// Writing a preview image (`lpmbake render`): EXR keeps scene-linear values in the working
// colour space (with its chromaticities), PNG gets the OCIO config's default sRGB view.
#pragma once

#include <string>
#include <vector>

#include "vdb_io/atomic_file.h"
#include "vdb_io/image_helper.h"

namespace lpm {

/// True for a path ending in .exr or .png (case-insensitive), the formats writePreviewImage takes.
bool isPreviewImagePath(const std::string& path);

/// What writePreviewImage stores for `path`: "<working> scene-linear" (EXR) or "sRGB view" (PNG).
std::string previewImageEncoding(const std::string& path, const std::string& workingSpace);

/// Writes `rgb` ([pixel][rgb], row 0 at the top) through `out` and commits it. The format
/// follows the final path's extension. Throws OutputError.
void writePreviewImage(AtomicOutput& out, std::vector<float> rgb, int width, int height,
                       const std::string& workingSpace);

/// The same through an encoder started earlier for out.tempPath() (image_helper.h), whose
/// OpenImageIO has loaded while the caller rendered.
void writePreviewImage(AtomicOutput& out, ImageEncode& encode, std::vector<float> rgb, int width, int height,
                       const std::string& workingSpace);

}  // namespace lpm
