// Status: the error type at the library's boundaries (readers, writers, option validation).
// A failed Status carries one line that names the file and the problem, so a CLI can print it as
// is.
#pragma once

#include <string>
#include <utility>

namespace mgsr {

class [[nodiscard]] Status {
 public:
  Status() = default;
  static Status Ok() { return Status(); }
  static Status Error(std::string message) { return Status(std::move(message)); }

  bool ok() const { return !failed_; }
  const std::string& message() const { return message_; }

  // Prefixes context ("reading scene: ") to a failed status; a no-op on success.
  Status WithContext(const std::string& context) const {
    return ok() ? *this : Status(context + message_);
  }

 private:
  explicit Status(std::string message) : failed_(true), message_(std::move(message)) {}
  bool failed_ = false;
  std::string message_;
};

}  // namespace mgsr

#define MGSR_RETURN_IF_ERROR(expr)               \
  do {                                           \
    ::mgsr::Status _mgsr_status = (expr);        \
    if (!_mgsr_status.ok()) return _mgsr_status; \
  } while (0)
