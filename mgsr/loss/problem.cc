#include "mgsr/loss/problem.h"

#include "mgsr/core/profiler.h"

namespace mgsr {

void Problem::AddTerm(std::unique_ptr<LossTerm> term, double weight, Branch branch,
                      std::string label) {
  if (label.empty()) label = term->Name();
  std::string profile_name = "loss: " + label;
  entries_.push_back({std::move(term), weight, branch, std::move(label), std::move(profile_name)});
}

bool Problem::SetWeight(const std::string& name, Branch branch, double weight) {
  for (Entry& e : entries_) {
    if (e.branch == branch && e.term->Name() == name) {
      e.weight = weight;
      return true;
    }
  }
  return false;
}

Status Problem::Check(Branch branch, const RenderBuffers& in, const Targets& targets) const {
  for (const Entry& e : entries_) {
    if (e.branch != branch || e.weight == 0) continue;
    const Status s = e.term->Check(in, targets);
    if (!s.ok()) return s.WithContext(e.label + ": ");
  }
  return Status::Ok();
}

double Problem::Evaluate(Branch branch, const RenderBuffers& in, const Targets& targets,
                         RenderGradients* grad, std::vector<TermValue>* breakdown) const {
  if (grad != nullptr) grad->Clear();
  double total = 0;
  size_t rows = 0;
  for (const Entry& e : entries_) {
    if (e.branch != branch || e.weight == 0) continue;
    ProfileScope scope(e.profile_name.c_str());
    const double v = e.term->Evaluate(in, targets, e.weight, grad);
    total += e.weight * v;
    if (breakdown != nullptr) SetTermValue(breakdown, rows++, e.label, e.weight, v);
  }
  if (breakdown != nullptr) breakdown->resize(rows);
  return total;
}

void Problem::SetTermValue(std::vector<TermValue>* values, size_t i, const std::string& name,
                           double weight, double value) {
  if (i == values->size()) {
    values->push_back({name, weight, value});
    return;
  }
  TermValue& t = (*values)[i];
  t.name.assign(name);
  t.weight = weight;
  t.value = value;
}

void Problem::EvaluateTargetGradient(Branch branch, const RenderBuffers& in, const Targets& targets,
                                     TargetGradients* grad) const {
  *grad = TargetGradients();
  for (const Entry& e : entries_) {
    if (e.branch != branch || e.weight == 0 || e.term->TargetInputs().empty()) continue;
    e.term->EvaluateTargetGradient(in, targets, e.weight, grad);
  }
}

}  // namespace mgsr
