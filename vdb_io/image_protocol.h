// The byte stream between lpmbake and its image helper (image_helper.h): a decoded image
// or an image to encode, as a few text lines and then the float RGB values raw.
//
//   lpmbake-image 1
//   width W
//   height H
//   KEY VALUE           (decoded: channels, colorspace, warning; to encode: png, attribute,
//   ...                  chromaticities)
//   floats N            (N = W * H * 3, then N native-endian floats)
//
// A value runs to the end of its line (newlines in it become spaces). Both ends are the
// same build of the same machine, so the floats need no byte-order conversion.
#pragma once

#include <cstddef>
#include <vector>

#include "vdb_io/image_codec.h"

namespace lpm {

/// Write to / read from a file descriptor. Reading throws std::runtime_error naming what is
/// missing or malformed; writing throws on a short write.
void writeDecodedImage(int fd, const DecodedImage& image);
/// How the float block's storage is made: `storage(v, n)` sizes v to n values (the block
/// is then read over them); null: v.resize(n). lpmbake passes assignZeroed
/// (core/malloc_policy.h): an 8192 x 4096 image is 400 MB, faulted in 4 KiB pages otherwise.
using FloatStorage = std::vector<float>& (*)(std::vector<float>&, std::size_t);
DecodedImage readDecodedImage(int fd, FloatStorage storage = nullptr);
void writeImageToEncode(int fd, const ImageToEncode& image);
ImageToEncode readImageToEncode(int fd);

}  // namespace lpm
