#include "mgsr/io/undistort.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <opencv2/imgproc.hpp>

namespace mgsr {
namespace {

// cv::remap places the top-left pixel's centre at (0, 0), COLMAP and Camera at (0.5, 0.5).
constexpr double kHalfPixel = 0.5;

}  // namespace

std::string Undistortion::Describe() const {
  char buffer[160];
  std::snprintf(buffer, sizeof(buffer),
                "undistorted to pinhole (bicubic remap), fx %.1f -> %.1f, fy %.1f -> %.1f", lens.fx,
                fx, lens.fy, fy);
  return lens.model + " lens (" + lens.CoefficientText() + ") " + buffer;
}

Status MakeUndistortion(const Lens& lens, bool with_maps, const std::string& where,
                        Undistortion* out) {
  Undistortion u;
  u.lens = lens;
  if (lens.IsPinhole()) {
    u.fx = lens.fx;
    u.fy = lens.fy;
    u.cx = lens.cx;
    u.cy = lens.cy;
    *out = std::move(u);
    return Status::Ok();
  }
  // The largest axis-aligned rectangle of undistorted (normalised) coordinates that the photo's
  // border encloses, spread over the whole pinhole image: every pinhole pixel sees the photo (as
  // OpenCV's getOptimalNewCameraMatrix with alpha 0). The border is walked along pixel edges.
  const int w = lens.width, h = lens.height;
  constexpr int kSamples = 64;
  double x_lo = -1e300, x_hi = 1e300, y_lo = -1e300, y_hi = 1e300;
  int failed = 0;
  const auto undistorted = [&](double px, double py, Eigen::Vector2d* xy) {
    const Eigen::Vector2d d((px - lens.cx) / lens.fx, (py - lens.cy) / lens.fy);
    const bool ok = lens.Undistort(d, xy);
    failed += !ok;
    return ok;
  };
  for (int i = 0; i <= kSamples; ++i) {
    const double s = static_cast<double>(i) / kSamples;
    Eigen::Vector2d xy;
    if (undistorted(0, s * h, &xy)) x_lo = std::max(x_lo, xy.x());
    if (undistorted(w, s * h, &xy)) x_hi = std::min(x_hi, xy.x());
    if (undistorted(s * w, 0, &xy)) y_lo = std::max(y_lo, xy.y());
    if (undistorted(s * w, h, &xy)) y_hi = std::min(y_hi, xy.y());
  }
  u.fx = w / (x_hi - x_lo);
  u.fy = h / (y_hi - y_lo);
  u.cx = -x_lo * u.fx;
  u.cy = -y_lo * u.fy;
  // A lens whose coefficients fold the image over (or a fisheye wider than a pinhole can show)
  // has no pinhole equivalent.
  const bool usable = failed == 0 && std::isfinite(u.fx) && std::isfinite(u.fy) &&
                      u.fx > 0.05 * lens.fx && u.fy > 0.05 * lens.fy && u.fx < 20 * lens.fx &&
                      u.fy < 20 * lens.fy && u.cx > 0 && u.cx < w && u.cy > 0 && u.cy < h;
  if (!usable) {
    char buffer[240];
    std::snprintf(buffer, sizeof(buffer),
                  ": the %s lens (%s) has no usable pinhole equivalent (fx %.4g -> %.4g, cx "
                  "%.4g -> %.4g, %d border points outside the model's range): check the "
                  "distortion coefficients",
                  lens.model.c_str(), lens.CoefficientText().c_str(), lens.fx, u.fx, lens.cx, u.cx,
                  failed);
    return Status::Error(where + buffer);
  }
  if (with_maps) {
    // Each pinhole pixel centre, through the lens, to the photo (OpenCV's pixel-centre origin).
    u.map_x.resize(static_cast<size_t>(w) * h);
    u.map_y.resize(u.map_x.size());
#pragma omp parallel for schedule(static)
    for (int y = 0; y < h; ++y) {
      for (int x = 0; x < w; ++x) {
        const Eigen::Vector2d d =
            lens.Distort({(x + kHalfPixel - u.cx) / u.fx, (y + kHalfPixel - u.cy) / u.fy});
        const size_t i = static_cast<size_t>(y) * w + x;
        u.map_x[i] = static_cast<float>(lens.fx * d.x() + lens.cx - kHalfPixel);
        u.map_y[i] = static_cast<float>(lens.fy * d.y() + lens.cy - kHalfPixel);
      }
    }
  }
  *out = std::move(u);
  return Status::Ok();
}

Image UndistortImage(const Undistortion& u, const Image& photo) {
  if (u.map_x.empty()) return photo;
  const int w = photo.width(), h = photo.height();
  Image out(w, h, photo.channels());
  const cv::Mat map_x(h, w, CV_32FC1, const_cast<float*>(u.map_x.data()));
  const cv::Mat map_y(h, w, CV_32FC1, const_cast<float*>(u.map_y.data()));
  for (int c = 0; c < photo.channels(); ++c) {
    const cv::Mat src(h, w, CV_32FC1, const_cast<float*>(photo.plane(c)));
    cv::Mat dst(h, w, CV_32FC1, out.plane(c));
    cv::remap(src, dst, map_x, map_y, cv::INTER_CUBIC, cv::BORDER_REPLICATE);
  }
  // Bicubic keeps edges sharper than bilinear (a blurred photo would score easier test views
  // than the capture has), and overshoots a little at them: back into [0, 1].
  float* v = out.data();
  for (size_t i = 0; i < out.size(); ++i) v[i] = std::min(1.0f, std::max(0.0f, v[i]));
  return out;
}

}  // namespace mgsr
