// ImageT: a planar buffer (channel-major: all of channel 0, then channel 1, ...), row-major
// within a channel. Planar layout lets the rasterizers and losses run vectorised loops per channel.
#pragma once

#include <cstddef>
#include <utility>
#include <vector>

namespace mgsr {

template <typename T>
class ImageT {
 public:
  ImageT() = default;
  ImageT(int width, int height, int channels, T fill = T(0))
      : width_(width),
        height_(height),
        channels_(channels),
        data_(static_cast<size_t>(width) * height * channels, fill) {}
  ImageT(const ImageT&) = default;
  ImageT& operator=(const ImageT&) = default;
  // A moved-from image is empty (0 x 0 x 0), not a shape without data.
  ImageT(ImageT&& o) noexcept
      : width_(o.width_), height_(o.height_), channels_(o.channels_), data_(std::move(o.data_)) {
    o.width_ = o.height_ = o.channels_ = 0;
    o.data_.clear();
  }
  ImageT& operator=(ImageT&& o) noexcept {
    if (this != &o) {
      width_ = o.width_;
      height_ = o.height_;
      channels_ = o.channels_;
      data_ = std::move(o.data_);
      o.width_ = o.height_ = o.channels_ = 0;
      o.data_.clear();
    }
    return *this;
  }

  int width() const { return width_; }
  int height() const { return height_; }
  int channels() const { return channels_; }
  bool empty() const { return data_.empty(); }
  size_t plane_size() const { return static_cast<size_t>(width_) * height_; }
  size_t size() const { return data_.size(); }

  T* data() { return data_.data(); }
  const T* data() const { return data_.data(); }
  T* plane(int c) { return data_.data() + c * plane_size(); }
  const T* plane(int c) const { return data_.data() + c * plane_size(); }
  T& at(int c, int y, int x) {
    return data_[c * plane_size() + static_cast<size_t>(y) * width_ + x];
  }
  T at(int c, int y, int x) const {
    return data_[c * plane_size() + static_cast<size_t>(y) * width_ + x];
  }

  void Fill(T v) { data_.assign(data_.size(), v); }
  // Reshapes to width x height x channels filled with `fill`, reusing the storage it already has
  // (no allocation when it is large enough: buffers kept across training iterations).
  void Reset(int width, int height, int channels, T fill = T(0)) {
    width_ = width;
    height_ = height;
    channels_ = channels;
    data_.assign(static_cast<size_t>(width) * height * channels, fill);
  }
  // Empty (0 x 0 x 0), keeping the storage for a later Reset.
  void Clear() {
    width_ = height_ = channels_ = 0;
    data_.clear();
  }
  void swap(ImageT& o) noexcept {
    std::swap(width_, o.width_);
    std::swap(height_, o.height_);
    std::swap(channels_, o.channels_);
    data_.swap(o.data_);
  }
  template <typename U>
  bool SameShape(const ImageT<U>& o) const {
    return width_ == o.width() && height_ == o.height() && channels_ == o.channels();
  }
  // A copy in another scalar type (e.g. double for gradient checks).
  template <typename U>
  ImageT<U> Cast() const {
    ImageT<U> out(width_, height_, channels_);
    for (size_t i = 0; i < data_.size(); ++i) out.data()[i] = static_cast<U>(data_[i]);
    return out;
  }

 private:
  int width_ = 0, height_ = 0, channels_ = 0;
  std::vector<T> data_;
};

// Renders, images and gradients are float; double images serve numeric gradient checks.
using Image = ImageT<float>;
using ImageD = ImageT<double>;

}  // namespace mgsr
