// Reading and writing images (PNG, JPEG, ... through OpenCV) as planar float Images in [0, 1].
// Values stay in the file's sRGB encoding, as in the reference implementation.
#pragma once

#include <string>

#include "mgsr/core/image.h"
#include "mgsr/core/status.h"

namespace mgsr {

// Keeps the file's channels: 1 (grey), 3 (RGB) or 4 (RGBA, straight alpha). 8- and 16-bit inputs.
Status ReadImage(const std::string& path, Image* image);

// Writes 1, 3 or 4 channels as 8-bit (values clamped to [0, 1]); the format follows the extension.
// Written atomically (temporary file + rename).
Status WriteImage(const std::string& path, const Image& image);

// The EXIF orientation of a JPEG (1..8, as the tag defines it: 1 upright, 3 turned 180 degrees,
// 6 and 8 turned a quarter, 2 4 5 7 mirrored); 1 when the file has none or is not a JPEG.
// COLMAP, nerfstudio and instant-ngp read the stored pixel grid and ignore this tag, so the
// loaders do too unless the camera says otherwise; the photo pipeline hands colmap upright copies.
int ExifOrientation(const std::string& path);
// The image as a viewer shows it: `orientation` (1..8) undone.
Image ApplyExifOrientation(const Image& image, int orientation);

// Area-averaging resize (for downscaling inputs) or bilinear when enlarging.
Image ResizeImage(const Image& image, int width, int height);

// Channels [first, first + count) as a new image.
Image ExtractChannels(const Image& image, int first, int count);

}  // namespace mgsr

namespace mgsr {

// Float maps (depth, normals) as PFM: 1 channel ("Pf") or 3 channels ("PF"), little-endian,
// rows stored bottom-to-top as the format requires. Lossless for float32.
Status WritePfm(const std::string& path, const Image& image);
Status ReadPfm(const std::string& path, Image* image);

}  // namespace mgsr
