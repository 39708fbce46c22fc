// Bounds-checked little-endian reading from an in-memory file, and appending writes. A read past
// the end reports "truncated" with the file name and offset instead of reading garbage.
#pragma once

#include <cstdint>
#include <cstring>
#include <string>
#include <type_traits>

#include "mgsr/core/status.h"

namespace mgsr {

class BinaryReader {
 public:
  BinaryReader(const std::string& path, const std::string& data) : path_(path), data_(data) {}

  template <typename T>
  Status Read(T* value) {
    static_assert(std::is_trivially_copyable<T>::value, "POD only");
    if (pos_ + sizeof(T) > data_.size()) return Truncated();
    std::memcpy(value, data_.data() + pos_, sizeof(T));  // the host is little-endian (x86_64)
    pos_ += sizeof(T);
    return Status::Ok();
  }
  // A '\0'-terminated string.
  Status ReadCString(std::string* s) {
    const size_t end = data_.find('\0', pos_);
    if (end == std::string::npos) return Truncated();
    s->assign(data_, pos_, end - pos_);
    pos_ = end + 1;
    return Status::Ok();
  }
  // Fails when fewer than count * bytes_each bytes remain: a corrupt count must not make us
  // allocate gigabytes before noticing.
  Status CheckRemaining(uint64_t count, uint64_t bytes_each, const char* what) const {
    const uint64_t remaining = data_.size() - pos_;
    if (bytes_each > 0 && count > remaining / bytes_each) {
      return Status::Error(path_ + ": truncated or corrupt (" + std::to_string(count) + " " + what +
                           " declared at byte " + std::to_string(pos_) + " but only " +
                           std::to_string(remaining) + " bytes remain)");
    }
    return Status::Ok();
  }
  bool AtEnd() const { return pos_ == data_.size(); }
  size_t position() const { return pos_; }
  const std::string& path() const { return path_; }

 private:
  Status Truncated() const {
    return Status::Error(path_ + ": truncated (unexpected end of file at byte " +
                         std::to_string(pos_) + " of " + std::to_string(data_.size()) + ")");
  }
  // The name is copied: callers pass literals ("cut.ckpt"), whose temporary std::string would be
  // gone by the first error (AddressSanitizer: stack-use-after-scope). The data, which can be
  // large, stays a reference: it must outlive the reader.
  std::string path_;
  const std::string& data_;
  size_t pos_ = 0;
};

class BinaryWriter {
 public:
  template <typename T>
  void Write(const T& value) {
    static_assert(std::is_trivially_copyable<T>::value, "POD only");
    data_.append(reinterpret_cast<const char*>(&value), sizeof(T));
  }
  void WriteCString(const std::string& s) {
    data_.append(s);
    data_.push_back('\0');
  }
  const std::string& data() const { return data_; }

 private:
  std::string data_;
};

}  // namespace mgsr
