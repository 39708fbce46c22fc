// Problem: the loss terms of both branches with their weights (Ceres' Problem for our image-space
// residuals). Evaluating a branch sums its weighted terms on that branch's render buffers and
// produces the summed gradient buffers, ready for the branch's render backward. Terms with weight
// 0 cost nothing; a per-term breakdown is available for logging.
#pragma once

#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "mgsr/core/status.h"
#include "mgsr/loss/loss_term.h"

namespace mgsr {

enum class Branch { kSurfels2D, kGaussians3D };

class Problem {
 public:
  struct Entry {
    std::unique_ptr<LossTerm> term;
    double weight;
    Branch branch;
    std::string label;         // the breakdown's name for the entry (default: the term's name)
    std::string profile_name;  // "loss: <label>", the entry's scope in a profile
  };
  struct TermValue {
    std::string name;
    double weight, value;  // value unweighted
  };
  // Sets (*values)[i], growing the list by one when i is its size: in place, so a list refilled
  // every step keeps its names' storage (no allocation once the rows are stable).
  static void SetTermValue(std::vector<TermValue>* values, size_t i, const std::string& name,
                           double weight, double value);

  void AddTerm(std::unique_ptr<LossTerm> term, double weight, Branch branch,
               std::string label = "");
  // Changes the weight of the first entry whose term name matches (schedules switch terms on and
  // off).
  bool SetWeight(const std::string& name, Branch branch, double weight);
  // Changes the weight of entry `index` (in the order added).
  void SetWeight(size_t index, double weight) { entries_.at(index).weight = weight; }
  const std::vector<Entry>& entries() const { return entries_; }

  // Checks every active term of the branch against the buffers and targets.
  Status Check(Branch branch, const RenderBuffers& in, const Targets& targets) const;
  // Weighted sum of the branch's terms; with grad, it is cleared and filled with d total / d
  // buffer.
  double Evaluate(Branch branch, const RenderBuffers& in, const Targets& targets,
                  RenderGradients* grad, std::vector<TermValue>* breakdown = nullptr) const;
  // Bidirectional supervision: the weighted sum of d term / d target over the branch's active
  // terms that differentiate the other branch's renders (LossTerm::TargetInputs); `grad` is
  // cleared first.
  void EvaluateTargetGradient(Branch branch, const RenderBuffers& in, const Targets& targets,
                              TargetGradients* grad) const;

 private:
  std::vector<Entry> entries_;
};

}  // namespace mgsr
