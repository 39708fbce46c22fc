// NamedRegistry: factories by name, an extension point of the library (loss terms, priors on the
// primitives, density strategies). A registry holds one kind of component; its factories take the
// component's arguments and a Status, and report a bad config there (or return null).
#pragma once

#include <functional>
#include <map>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "mgsr/core/status.h"

namespace mgsr {

template <typename T, typename... Args>
class NamedRegistry {
 public:
  using Factory = std::function<std::unique_ptr<T>(Args..., Status* status)>;

  // `kind` names the component in errors ("loss term"), `quote` is put around a name there.
  NamedRegistry(std::string kind, char quote) : kind_(std::move(kind)), quote_(quote) {}

  void Register(const std::string& name, Factory factory) { factories_[name] = std::move(factory); }
  bool Has(const std::string& name) const { return factories_.count(name) != 0; }
  // nullptr and a message naming the component and the problem when the name or the arguments
  // are bad.
  std::unique_ptr<T> Create(const std::string& name, Args... args, Status* status) const {
    const std::string quoted = quote_ + name + quote_;
    const auto it = factories_.find(name);
    if (it == factories_.end()) {
      std::string known;
      for (const auto& [n, f] : factories_) known += (known.empty() ? "" : ", ") + n;
      *status = Status::Error("unknown " + kind_ + " " + quoted + " (known: " + known + ")");
      return nullptr;
    }
    *status = Status::Ok();
    std::unique_ptr<T> made = it->second(args..., status);
    if (made == nullptr && status->ok())
      *status = Status::Error(kind_ + " " + quoted + " could not be created");
    if (!status->ok()) *status = status->WithContext(kind_ + " " + quoted + ": ");
    return status->ok() ? std::move(made) : nullptr;
  }
  std::vector<std::string> Names() const {
    std::vector<std::string> names;
    for (const auto& [n, f] : factories_) names.push_back(n);
    return names;
  }

 private:
  std::string kind_;
  char quote_;
  std::map<std::string, Factory> factories_;
};

}  // namespace mgsr
