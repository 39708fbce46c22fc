#include "mgsr/mesh/fusion_region.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <nlohmann/json.hpp>
#include <sstream>

#include "mgsr/io/file_util.h"
#include "mgsr/mesh/tsdf_fusion.h"

namespace mgsr {

Eigen::AlignedBox3d RegionFromCameras(const std::vector<Camera>& cameras, double min_share,
                                      int grid) {
  Eigen::AlignedBox3d region;  // empty
  if (cameras.empty() || grid < 2) return region;
  const Eigen::Vector3d centre = LookAtCenter(cameras);
  std::vector<double> distances;
  for (const Camera& c : cameras) distances.push_back((c.Center() - centre).norm());
  std::nth_element(distances.begin(), distances.begin() + distances.size() / 2, distances.end());
  const double half = distances[distances.size() / 2];
  if (!(half > 0)) return region;
  const double step = 2 * half / (grid - 1);
  const int needed = std::max(1, static_cast<int>(std::ceil(min_share * cameras.size() - 1e-9)));
  for (int k = 0; k < grid; ++k) {
    for (int j = 0; j < grid; ++j) {
      for (int i = 0; i < grid; ++i) {
        const Eigen::Vector3d X =
            centre + Eigen::Vector3d(i, j, k) * step - Eigen::Vector3d::Constant(half);
        int seen = 0;
        for (const Camera& c : cameras) {
          const Eigen::Vector3d Xc = c.WorldToCamera(X);
          if (!(Xc.z() > 1e-6)) continue;
          const Eigen::Vector2d uv = c.CameraToPixel(Xc);
          if (uv.x() >= 0 && uv.y() >= 0 && uv.x() <= c.width && uv.y() <= c.height) ++seen;
        }
        if (seen >= needed) region.extend(X);
      }
    }
  }
  if (!region.isEmpty()) {
    region.min() -= Eigen::Vector3d::Constant(step);
    region.max() += Eigen::Vector3d::Constant(step);
  }
  return region;
}

Status ParseRegion(const std::string& text, Eigen::AlignedBox3d* region) {
  double v[6];
  char extra = 0;
  if (std::sscanf(text.c_str(), "%lf,%lf,%lf,%lf,%lf,%lf%c", &v[0], &v[1], &v[2], &v[3], &v[4],
                  &v[5], &extra) == 6) {
    for (double x : v) {
      if (!std::isfinite(x)) return Status::Error("region '" + text + "': not finite");
    }
    *region =
        Eigen::AlignedBox3d(Eigen::Vector3d(v[0], v[1], v[2]), Eigen::Vector3d(v[3], v[4], v[5]));
  } else {
    std::string data;
    if (!ReadFileToString(text, &data).ok()) {
      return Status::Error("region '" + text +
                           "': neither x0,y0,z0,x1,y1,z1 nor a readable JSON file");
    }
    const nlohmann::json j = nlohmann::json::parse(data, nullptr, false);
    const auto corner = [&](const char* key, Eigen::Vector3d* p) {
      if (!j.is_object() || !j.contains(key) || !j[key].is_array() || j[key].size() != 3)
        return false;
      for (int k = 0; k < 3; ++k) {
        if (!j[key][k].is_number()) return false;
        (*p)[k] = j[key][k].get<double>();
        if (!std::isfinite((*p)[k])) return false;
      }
      return true;
    };
    Eigen::Vector3d lo, hi;
    if (!corner("min", &lo) || !corner("max", &hi))
      return Status::Error(text + ": a region file needs \"min\" and \"max\" arrays of 3 numbers");
    *region = Eigen::AlignedBox3d(lo, hi);
  }
  if (!((region->max().array() > region->min().array()).all()))
    return Status::Error("region '" + text + "': every max must exceed its min");
  return Status::Ok();
}

std::string RegionToString(const Eigen::AlignedBox3d& r) {
  char buf[160];
  std::snprintf(buf, sizeof(buf), "[%.3g, %.3g, %.3g] .. [%.3g, %.3g, %.3g]", r.min().x(),
                r.min().y(), r.min().z(), r.max().x(), r.max().y(), r.max().z());
  return buf;
}

std::vector<bool> TrianglesOutside(const Eigen::AlignedBox3d& region,
                                   const std::vector<Eigen::Vector3d>& vertices,
                                   const std::vector<Eigen::Vector3i>& triangles) {
  std::vector<bool> inside(vertices.size());
  for (size_t v = 0; v < vertices.size(); ++v) inside[v] = region.contains(vertices[v]);
  std::vector<bool> outside(triangles.size());
  for (size_t t = 0; t < triangles.size(); ++t) {
    const Eigen::Vector3i& f = triangles[t];
    outside[t] = !inside[f[0]] || !inside[f[1]] || !inside[f[2]];
  }
  return outside;
}

void CropMeshToRegion(const Eigen::AlignedBox3d& region, TriangleMesh* mesh) {
  const std::vector<bool> outside = TrianglesOutside(region, mesh->vertices, mesh->triangles);
  std::vector<int> remap(mesh->vertices.size(), -1);
  TriangleMesh out;
  for (size_t t = 0; t < mesh->triangles.size(); ++t) {
    if (outside[t]) continue;
    const Eigen::Vector3i& f = mesh->triangles[t];
    Eigen::Vector3i g;
    for (int k = 0; k < 3; ++k) {
      int& r = remap[f[k]];
      if (r < 0) {
        r = static_cast<int>(out.vertices.size());
        out.vertices.push_back(mesh->vertices[f[k]]);
        if (!mesh->vertex_normals.empty()) out.vertex_normals.push_back(mesh->vertex_normals[f[k]]);
        if (!mesh->vertex_colors.empty()) out.vertex_colors.push_back(mesh->vertex_colors[f[k]]);
      }
      g[k] = r;
    }
    out.triangles.push_back(g);
  }
  *mesh = std::move(out);
}

}  // namespace mgsr
