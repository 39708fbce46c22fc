#include "mgsr/io/image_io.h"

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>
#include <vector>

#include "mgsr/io/file_util.h"

namespace mgsr {
namespace {

// cv::Mat (interleaved, BGR order) <-> planar RGB float.
Image FromMat(const cv::Mat& mat_in) {
  cv::Mat mat;
  const double scale = mat_in.depth() == CV_16U  ? 1.0 / 65535.0
                       : mat_in.depth() == CV_8U ? 1.0 / 255.0
                                                 : 1.0;
  mat_in.convertTo(mat, CV_32F, scale);
  const int c = mat.channels();
  Image image(mat.cols, mat.rows, c);
  std::vector<cv::Mat> planes;
  cv::split(mat, planes);
  for (int k = 0; k < c; ++k) {
    // OpenCV stores B, G, R, A; we store R, G, B, A.
    const int src = (c >= 3 && k < 3) ? 2 - k : k;
    cv::Mat dst(mat.rows, mat.cols, CV_32F, image.plane(k));
    planes[src].copyTo(dst);
  }
  return image;
}

cv::Mat ToMat8(const Image& image) {
  const int c = image.channels();
  std::vector<cv::Mat> planes(c);
  for (int k = 0; k < c; ++k) {
    const int src = (c >= 3 && k < 3) ? 2 - k : k;
    cv::Mat p(image.height(), image.width(), CV_32F, const_cast<float*>(image.plane(src)));
    p.convertTo(planes[k], CV_8U, 255.0);  // saturate_cast clamps and rounds
  }
  cv::Mat out;
  cv::merge(planes, out);
  return out;
}

}  // namespace

int ExifOrientation(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::string head(1 << 17, '\0');
  in.read(&head[0], static_cast<std::streamsize>(head.size()));
  head.resize(static_cast<size_t>(in.gcount()));
  const auto byte = [&](size_t i) { return static_cast<uint8_t>(head[i]); };
  if (head.size() < 4 || byte(0) != 0xFF || byte(1) != 0xD8) return 1;  // not a JPEG
  // JPEG segments up to the image data: APP1 "Exif\0\0" holds a TIFF header and IFD0.
  size_t p = 2;
  while (p + 4 <= head.size() && byte(p) == 0xFF) {
    const uint8_t marker = byte(p + 1);
    const size_t length = (static_cast<size_t>(byte(p + 2)) << 8) | byte(p + 3);
    if (marker == 0xDA || length < 2) break;  // start of scan: no more metadata
    const size_t body = p + 4, end = p + 2 + length;
    if (marker == 0xE1 && end <= head.size() && length >= 8 &&
        head.compare(body, 6, std::string("Exif\0\0", 6)) == 0) {
      const size_t tiff = body + 6;
      if (tiff + 8 > end) return 1;
      const bool little = head[tiff] == 'I';
      const auto u16 = [&](size_t i) {
        return little ? static_cast<uint32_t>(byte(i) | (byte(i + 1) << 8))
                      : static_cast<uint32_t>((byte(i) << 8) | byte(i + 1));
      };
      const auto u32 = [&](size_t i) {
        return little ? (u16(i) | (u16(i + 2) << 16)) : ((u16(i) << 16) | u16(i + 2));
      };
      const size_t ifd = tiff + u32(tiff + 4);
      if (ifd + 2 > end) return 1;
      const uint32_t entries = u16(ifd);
      for (uint32_t k = 0; k < entries; ++k) {
        const size_t e = ifd + 2 + 12 * k;
        if (e + 12 > end) return 1;
        if (u16(e) == 0x0112) {  // Orientation, SHORT
          const uint32_t v = u16(e + 8);
          return v >= 1 && v <= 8 ? static_cast<int>(v) : 1;
        }
      }
      return 1;
    }
    p = end;
  }
  return 1;
}

Image ApplyExifOrientation(const Image& image, int orientation) {
  if (orientation <= 1 || orientation > 8) return image;
  const int w = image.width(), h = image.height();
  const bool swap = orientation >= 5;  // 5..8 turn a quarter: width and height trade places
  Image out(swap ? h : w, swap ? w : h, image.channels());
  for (int c = 0; c < image.channels(); ++c) {
    for (int y = 0; y < out.height(); ++y) {
      for (int x = 0; x < out.width(); ++x) {
        // The stored pixel shown at (x, y), per the tag's definition of row 0 and column 0.
        int sx = x, sy = y;
        switch (orientation) {
          case 2:
            sx = w - 1 - x;
            break;
          case 3:
            sx = w - 1 - x;
            sy = h - 1 - y;
            break;
          case 4:
            sy = h - 1 - y;
            break;
          case 5:
            sx = y;
            sy = x;
            break;
          case 6:
            sx = y;
            sy = h - 1 - x;
            break;
          case 7:
            sx = w - 1 - y;
            sy = h - 1 - x;
            break;
          case 8:
            sx = w - 1 - y;
            sy = x;
            break;
        }
        out.at(c, y, x) = image.at(c, sy, sx);
      }
    }
  }
  return out;
}

Status ReadImage(const std::string& path, Image* image) {
  if (!FileExists(path)) return Status::Error(path + ": image file is missing");
  cv::Mat mat;
  try {
    mat = cv::imread(path, cv::IMREAD_UNCHANGED);
  } catch (const cv::Exception&) {
    mat.release();
  }
  if (mat.empty())
    return Status::Error(path + ": cannot decode image (corrupt or unsupported format)");
  if (mat.channels() != 1 && mat.channels() != 3 && mat.channels() != 4) {
    return Status::Error(path + ": unsupported channel count " + std::to_string(mat.channels()));
  }
  *image = FromMat(mat);
  return Status::Ok();
}

Status WriteImage(const std::string& path, const Image& image) {
  if (image.empty()) return Status::Error(path + ": refusing to write an empty image");
  if (image.channels() != 1 && image.channels() != 3 && image.channels() != 4) {
    return Status::Error(path + ": cannot write an image with " + std::to_string(image.channels()) +
                         " channels");
  }
  const size_t dot = path.find_last_of('.');
  const std::string ext = dot == std::string::npos ? ".png" : path.substr(dot);
  std::vector<uchar> buffer;
  try {
    if (!cv::imencode(ext, ToMat8(image), buffer)) {
      return Status::Error(path + ": cannot encode image as " + ext);
    }
  } catch (const cv::Exception& e) {
    return Status::Error(path + ": cannot encode image as " + ext);
  }
  return WriteStringToFileAtomic(path, std::string(buffer.begin(), buffer.end()));
}

Image ResizeImage(const Image& image, int width, int height) {
  if (width == image.width() && height == image.height()) return image;
  Image out(width, height, image.channels());
  const int interp = (width < image.width()) ? cv::INTER_AREA : cv::INTER_LINEAR;
  for (int k = 0; k < image.channels(); ++k) {
    cv::Mat src(image.height(), image.width(), CV_32F, const_cast<float*>(image.plane(k)));
    cv::Mat dst(height, width, CV_32F, out.plane(k));
    cv::resize(src, dst, cv::Size(width, height), 0, 0, interp);
  }
  return out;
}

Image ExtractChannels(const Image& image, int first, int count) {
  Image out(image.width(), image.height(), count);
  std::copy(image.plane(first), image.plane(first) + count * image.plane_size(), out.data());
  return out;
}

}  // namespace mgsr

namespace mgsr {

Status WritePfm(const std::string& path, const Image& image) {
  if (image.channels() != 1 && image.channels() != 3) {
    return Status::Error(path + ": PFM holds 1 or 3 channels, not " +
                         std::to_string(image.channels()));
  }
  std::string out = (image.channels() == 1 ? "Pf\n" : "PF\n") + std::to_string(image.width()) +
                    " " + std::to_string(image.height()) + "\n-1.0\n";
  const int w = image.width(), h = image.height(), c = image.channels();
  std::vector<float> row(static_cast<size_t>(w) * c);
  for (int y = h - 1; y >= 0; --y) {
    for (int x = 0; x < w; ++x) {
      for (int k = 0; k < c; ++k) row[x * c + k] = image.at(k, y, x);
    }
    out.append(reinterpret_cast<const char*>(row.data()), row.size() * sizeof(float));
  }
  return WriteStringToFileAtomic(path, out);
}

Status ReadPfm(const std::string& path, Image* image) {
  std::string data;
  MGSR_RETURN_IF_ERROR(ReadFileToString(path, &data));
  std::istringstream header(data);
  std::string magic;
  int w = 0, h = 0;
  double scale = 0;
  if (!(header >> magic >> w >> h >> scale) || (magic != "Pf" && magic != "PF") || w <= 0 ||
      h <= 0) {
    return Status::Error(path + ": not a PFM file (bad header)");
  }
  if (scale > 0) return Status::Error(path + ": big-endian PFM is not supported");
  const size_t offset = static_cast<size_t>(header.tellg()) + 1;  // one whitespace after the scale
  const int c = magic == "Pf" ? 1 : 3;
  const size_t bytes = static_cast<size_t>(w) * h * c * sizeof(float);
  if (data.size() < offset + bytes) return Status::Error(path + ": truncated PFM data");
  Image out(w, h, c);
  const float* src = reinterpret_cast<const float*>(data.data() + offset);
  std::vector<float> tmp(static_cast<size_t>(w) * h * c);
  std::memcpy(tmp.data(), src, bytes);
  for (int y = 0; y < h; ++y) {
    const float* row = tmp.data() + static_cast<size_t>(h - 1 - y) * w * c;
    for (int x = 0; x < w; ++x) {
      for (int k = 0; k < c; ++k) out.at(k, y, x) = row[x * c + k];
    }
  }
  *image = std::move(out);
  return Status::Ok();
}

}  // namespace mgsr
