#include "mgsr/io/model_ply.h"

#include <cmath>

#include "mgsr/io/ply.h"

namespace mgsr {
namespace {

void AddStrided(PlyElement* e, const std::string& name, const std::vector<float>& v, size_t stride,
                size_t offset) {
  std::vector<double> col(e->count);
  for (size_t i = 0; i < e->count; ++i) col[i] = v[i * stride + offset];
  e->AddColumn(name, "float", std::move(col));
}

// SH block [n][k][c] -> f_dc_c (k = 0) and f_rest_{c*(K-1)+k-1}.
void AddSh(PlyElement* e, const std::string& prefix, const std::vector<float>& sh, int K) {
  for (int c = 0; c < 3; ++c) AddStrided(e, prefix + "f_dc_" + std::to_string(c), sh, K * 3, c);
  for (int c = 0; c < 3; ++c) {
    for (int k = 1; k < K; ++k) {
      AddStrided(e, prefix + "f_rest_" + std::to_string(c * (K - 1) + k - 1), sh, K * 3, k * 3 + c);
    }
  }
}

Status GetStrided(const PlyElement& e, const std::string& path, const std::string& name,
                  std::vector<float>* v, size_t stride, size_t offset) {
  int p = -1;
  MGSR_RETURN_IF_ERROR(e.FindScalar(path, name, &p));
  if (p < 0) return Status::Error(path + ": missing vertex property '" + name + "'");
  for (size_t i = 0; i < e.count; ++i) {
    const double x = e.columns[p][i];
    if (!std::isfinite(x))
      return Status::Error(path + ": NaN/inf in '" + name + "' at vertex " + std::to_string(i));
    (*v)[i * stride + offset] = static_cast<float>(x);
  }
  return Status::Ok();
}

// Highest SH degree whose f_rest attributes are all present.
int DetectShDegree(const PlyElement& e, const std::string& prefix) {
  int n = 0;
  while (e.FindProperty(prefix + "f_rest_" + std::to_string(n)) >= 0) ++n;
  const int K = n / 3 + 1;
  for (int d = 0; d <= 3; ++d) {
    if (NumShCoeffs(d) == K) return d;
  }
  return -1;
}

Status GetSh(const PlyElement& e, const std::string& path, const std::string& prefix, int K,
             std::vector<float>* sh) {
  for (int c = 0; c < 3; ++c) {
    MGSR_RETURN_IF_ERROR(GetStrided(e, path, prefix + "f_dc_" + std::to_string(c), sh, K * 3, c));
  }
  for (int c = 0; c < 3; ++c) {
    for (int k = 1; k < K; ++k) {
      MGSR_RETURN_IF_ERROR(GetStrided(
          e, path, prefix + "f_rest_" + std::to_string(c * (K - 1) + k - 1), sh, K * 3, k * 3 + c));
    }
  }
  return Status::Ok();
}

PlyElement MakeVertexElement(size_t n, const std::vector<float>& means) {
  PlyElement e;
  e.name = "vertex";
  e.count = n;
  AddStrided(&e, "x", means, 3, 0);
  AddStrided(&e, "y", means, 3, 1);
  AddStrided(&e, "z", means, 3, 2);
  for (const char* name : {"nx", "ny", "nz"})
    e.AddColumn(name, "float", std::vector<double>(n, 0.0));
  return e;
}

Status ReadVertexElement(const std::string& path, PlyData* ply, const PlyElement** e) {
  MGSR_RETURN_IF_ERROR(ReadPly(path, ply));
  *e = ply->FindElement("vertex");
  if (*e == nullptr) return Status::Error(path + ": no 'vertex' element");
  return Status::Ok();
}

constexpr float kLogitOfTenth = -2.1972245773362196f;  // sigmoid^-1(0.1)

}  // namespace

void SetPlainReflection(GaussianModel* m) {
  const int K = m->sh_coeffs();
  for (size_t i = 0; i < m->size(); ++i) {
    for (int c = 0; c < 3; ++c) m->ref_sh[i * K * 3 + c] = m->sh[i * K * 3 + c];
    m->ref_opacity_logits[i] = kLogitOfTenth;
    m->beta_logits[i] = kLogitOfTenth;
  }
}

Status WriteGaussianPly(const std::string& path, const GaussianModel& m) {
  const size_t n = m.size();
  const int K = m.sh_coeffs();
  PlyData ply;
  ply.comments.push_back("MGSR-CPU 3DGS branch (reflection-aware), sh_degree " +
                         std::to_string(m.max_sh_degree));
  PlyElement e = MakeVertexElement(n, m.means);
  AddSh(&e, "", m.sh, K);
  AddStrided(&e, "opacity", m.opacity_logits, 1, 0);
  for (int d = 0; d < 3; ++d) AddStrided(&e, "scale_" + std::to_string(d), m.log_scales, 3, d);
  for (int d = 0; d < 4; ++d) AddStrided(&e, "rot_" + std::to_string(d), m.quats, 4, d);
  AddSh(&e, "ref_", m.ref_sh, K);
  AddStrided(&e, "ref_opacity", m.ref_opacity_logits, 1, 0);
  AddStrided(&e, "beta", m.beta_logits, 1, 0);
  ply.elements.push_back(std::move(e));
  return WritePly(path, ply);
}

Status ReadGaussianPly(const std::string& path, GaussianModel* m) {
  PlyData ply;
  const PlyElement* e = nullptr;
  MGSR_RETURN_IF_ERROR(ReadVertexElement(path, &ply, &e));
  const int degree = DetectShDegree(*e, "");
  if (degree < 0)
    return Status::Error(path + ": f_rest_* attributes do not match any SH degree 0-3");
  GaussianModel out;
  out.max_sh_degree = degree;
  out.Resize(e->count);
  const int K = out.sh_coeffs();
  for (int d = 0; d < 3; ++d)
    MGSR_RETURN_IF_ERROR(GetStrided(*e, path, std::string(1, "xyz"[d]), &out.means, 3, d));
  MGSR_RETURN_IF_ERROR(GetSh(*e, path, "", K, &out.sh));
  MGSR_RETURN_IF_ERROR(GetStrided(*e, path, "opacity", &out.opacity_logits, 1, 0));
  for (int d = 0; d < 3; ++d)
    MGSR_RETURN_IF_ERROR(GetStrided(*e, path, "scale_" + std::to_string(d), &out.log_scales, 3, d));
  for (int d = 0; d < 4; ++d)
    MGSR_RETURN_IF_ERROR(GetStrided(*e, path, "rot_" + std::to_string(d), &out.quats, 4, d));
  if (e->FindProperty("ref_f_dc_0") >= 0) {
    if (DetectShDegree(*e, "ref_") != degree)
      return Status::Error(path + ": reflected SH degree differs from transmitted");
    MGSR_RETURN_IF_ERROR(GetSh(*e, path, "ref_", K, &out.ref_sh));
    MGSR_RETURN_IF_ERROR(GetStrided(*e, path, "ref_opacity", &out.ref_opacity_logits, 1, 0));
    MGSR_RETURN_IF_ERROR(GetStrided(*e, path, "beta", &out.beta_logits, 1, 0));
  } else {
    SetPlainReflection(&out);
  }
  *m = std::move(out);
  return Status::Ok();
}

Status WriteSurfelPly(const std::string& path, const SurfelModel& m) {
  const size_t n = m.size();
  PlyData ply;
  ply.comments.push_back("MGSR-CPU 2DGS branch (surfels), sh_degree " +
                         std::to_string(m.max_sh_degree));
  PlyElement e = MakeVertexElement(n, m.means);
  AddSh(&e, "", m.sh, m.sh_coeffs());
  AddStrided(&e, "opacity", m.opacity_logits, 1, 0);
  for (int d = 0; d < 2; ++d) AddStrided(&e, "scale_" + std::to_string(d), m.log_scales, 2, d);
  for (int d = 0; d < 4; ++d) AddStrided(&e, "rot_" + std::to_string(d), m.quats, 4, d);
  ply.elements.push_back(std::move(e));
  return WritePly(path, ply);
}

Status ReadSurfelPly(const std::string& path, SurfelModel* m) {
  PlyData ply;
  const PlyElement* e = nullptr;
  MGSR_RETURN_IF_ERROR(ReadVertexElement(path, &ply, &e));
  const int degree = DetectShDegree(*e, "");
  if (degree < 0)
    return Status::Error(path + ": f_rest_* attributes do not match any SH degree 0-3");
  if (e->FindProperty("scale_2") >= 0)
    return Status::Error(path + ": has three scales; this is a 3DGS file, not a surfel file");
  SurfelModel out;
  out.max_sh_degree = degree;
  out.Resize(e->count);
  for (int d = 0; d < 3; ++d)
    MGSR_RETURN_IF_ERROR(GetStrided(*e, path, std::string(1, "xyz"[d]), &out.means, 3, d));
  MGSR_RETURN_IF_ERROR(GetSh(*e, path, "", out.sh_coeffs(), &out.sh));
  MGSR_RETURN_IF_ERROR(GetStrided(*e, path, "opacity", &out.opacity_logits, 1, 0));
  for (int d = 0; d < 2; ++d)
    MGSR_RETURN_IF_ERROR(GetStrided(*e, path, "scale_" + std::to_string(d), &out.log_scales, 2, d));
  for (int d = 0; d < 4; ++d)
    MGSR_RETURN_IF_ERROR(GetStrided(*e, path, "rot_" + std::to_string(d), &out.quats, 4, d));
  *m = std::move(out);
  return Status::Ok();
}

}  // namespace mgsr
