// Image: a planar float buffer (channel-major: all of channel 0, then channel 1, ...), row-major
// within a channel. Planar layout lets the rasterizers and losses run vectorised loops per channel.
#pragma once

#include <cstddef>
#include <vector>

namespace mgsr {

class Image {
 public:
  Image() = default;
  Image(int width, int height, int channels, float fill = 0.0f)
      : width_(width), height_(height), channels_(channels),
        data_(static_cast<size_t>(width) * height * channels, fill) {}

  int width() const { return width_; }
  int height() const { return height_; }
  int channels() const { return channels_; }
  bool empty() const { return data_.empty(); }
  size_t plane_size() const { return static_cast<size_t>(width_) * height_; }
  size_t size() const { return data_.size(); }

  float* data() { return data_.data(); }
  const float* data() const { return data_.data(); }
  float* plane(int c) { return data_.data() + c * plane_size(); }
  const float* plane(int c) const { return data_.data() + c * plane_size(); }
  float& at(int c, int y, int x) { return data_[c * plane_size() + static_cast<size_t>(y) * width_ + x]; }
  float at(int c, int y, int x) const {
    return data_[c * plane_size() + static_cast<size_t>(y) * width_ + x];
  }

  void Fill(float v) { data_.assign(data_.size(), v); }
  bool SameShape(const Image& o) const {
    return width_ == o.width_ && height_ == o.height_ && channels_ == o.channels_;
  }

 private:
  int width_ = 0, height_ = 0, channels_ = 0;
  std::vector<float> data_;
};

}  // namespace mgsr
