// Detailed built-in shapes: what smooth shapes cannot test (deep grooves, a through-hole, a narrow
// slot, a thin tube with close strands, a flat printed wall). Each is closed and outward-wound;
// shapes with sharp edges carry no vertex normals, so the ray caster shades them with face normals
// and their ground-truth normals are exact.
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>

#include "mgsr/synth/shapes.h"

namespace mgsr {
namespace {

constexpr double kPi = 3.14159265358979323846;

// Twice the signed area of a 2D polygon (counter-clockwise positive).
double SignedArea2(const std::vector<Eigen::Vector2d>& poly) {
  double a = 0;
  for (size_t i = 0; i < poly.size(); ++i) {
    const Eigen::Vector2d& p = poly[i];
    const Eigen::Vector2d& q = poly[(i + 1) % poly.size()];
    a += p.x() * q.y() - q.x() * p.y();
  }
  return a;
}

double Cross2(const Eigen::Vector2d& a, const Eigen::Vector2d& b, const Eigen::Vector2d& c) {
  return (b - a).x() * (c - a).y() - (b - a).y() * (c - a).x();
}

// Ear clipping of a simple counter-clockwise polygon: triangles as index triples into `poly`.
std::vector<Eigen::Vector3i> Triangulate(const std::vector<Eigen::Vector2d>& poly) {
  std::vector<int> idx(poly.size());
  for (size_t i = 0; i < idx.size(); ++i) idx[i] = static_cast<int>(i);
  std::vector<Eigen::Vector3i> tris;
  size_t guard = 0;
  while (idx.size() > 3 && guard++ < 4 * poly.size() * poly.size()) {
    bool clipped = false;
    for (size_t i = 0; i < idx.size(); ++i) {
      const int a = idx[(i + idx.size() - 1) % idx.size()], b = idx[i],
                c = idx[(i + 1) % idx.size()];
      if (Cross2(poly[a], poly[b], poly[c]) <= 1e-12) continue;  // reflex or degenerate
      bool inside = false;
      for (int k : idx) {
        if (k == a || k == b || k == c) continue;
        if (Cross2(poly[a], poly[b], poly[k]) >= 0 && Cross2(poly[b], poly[c], poly[k]) >= 0 &&
            Cross2(poly[c], poly[a], poly[k]) >= 0) {
          inside = true;
          break;
        }
      }
      if (inside) continue;
      tris.emplace_back(a, b, c);
      idx.erase(idx.begin() + static_cast<long>(i));
      clipped = true;
      break;
    }
    if (!clipped) break;
  }
  if (idx.size() == 3) tris.emplace_back(idx[0], idx[1], idx[2]);
  return tris;
}

// A prism: the simple polygon `poly` (x, y; any orientation) extruded from z = -half to +half.
// Walls are split into `rings` bands so that no triangle is very long.
TriangleMesh Extrude(std::vector<Eigen::Vector2d> poly, double half, int rings) {
  if (SignedArea2(poly) < 0) std::reverse(poly.begin(), poly.end());
  const int n = static_cast<int>(poly.size());
  TriangleMesh m;
  for (int r = 0; r <= rings; ++r) {
    const double z = -half + 2 * half * r / rings;
    for (const auto& p : poly) m.vertices.emplace_back(p.x(), p.y(), z);
  }
  for (int r = 0; r < rings; ++r) {
    for (int i = 0; i < n; ++i) {
      const int a = r * n + i, b = r * n + (i + 1) % n, c = a + n, d = b + n;
      // Counter-clockwise polygon: the outward normal of edge (p_i, p_i+1) is (dy, -dx).
      m.triangles.emplace_back(a, b, d);
      m.triangles.emplace_back(a, d, c);
    }
  }
  const std::vector<Eigen::Vector3i> cap = Triangulate(poly);
  const int top = rings * n;
  for (const auto& t : cap) {
    m.triangles.emplace_back(top + t[0], top + t[1], top + t[2]);  // +z, counter-clockwise
    m.triangles.emplace_back(t[0], t[2], t[1]);                    // -z
  }
  return m;
}

// A ring-shaped prism: outer outline r_out(theta) and a round hole of radius r_in, both sampled at
// the same angles, the caps as strips between them.
TriangleMesh ExtrudeAnnulus(const std::vector<double>& theta, const std::vector<double>& r_out,
                            double r_in, double half, int rings) {
  const int n = static_cast<int>(theta.size());
  TriangleMesh m;
  // Vertex blocks: outer rings 0..rings, then inner rings 0..rings.
  for (int side = 0; side < 2; ++side) {
    for (int r = 0; r <= rings; ++r) {
      const double z = -half + 2 * half * r / rings;
      for (int i = 0; i < n; ++i) {
        const double rad = side == 0 ? r_out[i] : r_in;
        m.vertices.emplace_back(rad * std::cos(theta[i]), rad * std::sin(theta[i]), z);
      }
    }
  }
  const int inner = (rings + 1) * n;
  for (int r = 0; r < rings; ++r) {
    for (int i = 0; i < n; ++i) {
      const int j = (i + 1) % n;
      const int a = r * n + i, b = r * n + j, c = a + n, d = b + n;
      m.triangles.emplace_back(a, b, d);  // outer wall, facing out
      m.triangles.emplace_back(a, d, c);
      m.triangles.emplace_back(inner + a, inner + d, inner + b);  // hole wall, facing the axis
      m.triangles.emplace_back(inner + a, inner + c, inner + d);
    }
  }
  for (int i = 0; i < n; ++i) {
    const int j = (i + 1) % n;
    const int ot = rings * n, it = inner + rings * n;  // top rings
    m.triangles.emplace_back(ot + i, ot + j, it + j);  // top cap (+z)
    m.triangles.emplace_back(ot + i, it + j, it + i);
    m.triangles.emplace_back(i, inner + j, j);  // bottom cap (-z)
    m.triangles.emplace_back(i, inner + i, inner + j);
  }
  return m;
}

// Rotates a mesh so that its z axis points along `axis` (a fixed tilt shows caps and walls alike).
void Tilt(TriangleMesh* m, const Eigen::Vector3d& axis) {
  const Eigen::Matrix3d R =
      Eigen::Quaterniond::FromTwoVectors(Eigen::Vector3d::UnitZ(), axis.normalized())
          .toRotationMatrix();
  for (auto& p : m->vertices) p = R * p;
}

}  // namespace

TriangleMesh MakeGear(int teeth, int samples_per_tooth) {
  // Trapezoidal teeth 0.24 deep on a root circle of 0.62, a hole of 0.25 through the middle.
  const double root = 0.62, tip = 0.86, hole = 0.25, half = 0.22;
  std::vector<double> theta, r;
  const int per = std::max(8, samples_per_tooth);
  for (int t = 0; t < teeth; ++t) {
    for (int s = 0; s < per; ++s) {
      const double f = static_cast<double>(s) / per;  // position within the tooth period
      // Root land [0, 0.3), rising flank [0.3, 0.4), tip land [0.4, 0.8), falling flank [0.8, 1).
      double rad;
      if (f < 0.3)
        rad = root;
      else if (f < 0.4)
        rad = root + (tip - root) * (f - 0.3) / 0.1;
      else if (f < 0.8)
        rad = tip;
      else
        rad = tip + (root - tip) * (f - 0.8) / 0.2;
      theta.push_back(2 * kPi * (t + f) / teeth);
      r.push_back(rad);
    }
  }
  TriangleMesh m = ExtrudeAnnulus(theta, r, hole, half, 4);
  Tilt(&m, Eigen::Vector3d(0.25, -0.35, 1.0));
  return m;  // sharp edges: no vertex normals
}

TriangleMesh MakeSlottedBlock(int segments) {
  // A U-shaped block 1.24 x 1.08 x 0.8: two walls 0.57 thick with a slot 0.1 wide and 0.9 deep
  // between them, on a base 0.18 thick.
  const double w = 0.62, slot = 0.05, floor_z = -0.4, top = 0.5, depth_half = 0.4;
  const std::vector<Eigen::Vector2d> u = {
      {-w, floor_z - 0.18}, {w, floor_z - 0.18}, {w, top},     {slot, top},
      {slot, floor_z},      {-slot, floor_z},    {-slot, top}, {-w, top}};
  TriangleMesh m = Extrude(u, depth_half, std::max(2, segments));
  // Profile in x-z, extruded along y: swap y and z (a mirror), then flip the winding back.
  for (auto& p : m.vertices) std::swap(p.y(), p.z());
  for (auto& t : m.triangles) std::swap(t[1], t[2]);
  Tilt(&m, Eigen::Vector3d(0.2, 0.15, 1.0));
  return m;
}

TriangleMesh MakeTrefoilKnot(int segments, int sides) {
  // The trefoil (sin t + 2 sin 2t, cos t - 2 cos 2t, -sin 3t), scaled to radius ~0.83, as a tube of
  // radius 0.12; frames by parallel transport, the twist left at the seam spread along the curve.
  const double scale = 0.27, tube = 0.12;
  auto c = [&](double t) -> Eigen::Vector3d {
    return Eigen::Vector3d(std::sin(t) + 2 * std::sin(2 * t), std::cos(t) - 2 * std::cos(2 * t),
                           -std::sin(3 * t)) *
           scale;
  };
  std::vector<Eigen::Vector3d> centre(segments), tangent(segments), normal(segments);
  for (int i = 0; i < segments; ++i) {
    const double t = 2 * kPi * i / segments, h = 1e-5;
    centre[i] = c(t);
    tangent[i] = (c(t + h) - c(t - h)).normalized();
  }
  normal[0] = tangent[0].unitOrthogonal();
  for (int i = 1; i < segments; ++i) {
    const Eigen::Vector3d n = normal[i - 1] - normal[i - 1].dot(tangent[i]) * tangent[i];
    normal[i] = n.normalized();
  }
  // Transport once more to the start: the angle between the result and normal[0] is the twist.
  Eigen::Vector3d back = normal[segments - 1] - normal[segments - 1].dot(tangent[0]) * tangent[0];
  back.normalize();
  const double twist = std::atan2(tangent[0].dot(back.cross(normal[0])), back.dot(normal[0]));
  TriangleMesh m;
  for (int i = 0; i < segments; ++i) {
    const double spread = twist * i / segments;
    const Eigen::Vector3d b0 = tangent[i].cross(normal[i]);
    const Eigen::Vector3d n = std::cos(spread) * normal[i] + std::sin(spread) * b0;
    const Eigen::Vector3d b = tangent[i].cross(n);
    for (int j = 0; j < sides; ++j) {
      const double a = 2 * kPi * j / sides;
      m.vertices.push_back(centre[i] + tube * (std::cos(a) * n + std::sin(a) * b));
    }
  }
  for (int i = 0; i < segments; ++i) {
    for (int j = 0; j < sides; ++j) {
      const int i1 = (i + 1) % segments, j1 = (j + 1) % sides;
      const int a = i * sides + j, b = i1 * sides + j, cc = i1 * sides + j1, d = i * sides + j1;
      // Around the tube +j turns from n towards b = tangent x n, so (+j) x tangent points out.
      m.triangles.emplace_back(a, cc, b);
      m.triangles.emplace_back(a, d, cc);
    }
  }
  m.ComputeVertexNormals();
  return m;
}

TriangleMesh MakePrintedWall() {
  // A slab 1.4 x 1.4 x 0.06 standing upright (its faces' normals along y), turned about z.
  const double half = 0.7, thick = 0.03;
  TriangleMesh m = Extrude({{-half, -half}, {half, -half}, {half, half}, {-half, half}}, thick, 1);
  // The faces lie in x-y; stand the slab up: (x, y, z) -> (x, z, y) is a mirror, so flip winding.
  for (auto& p : m.vertices) std::swap(p.y(), p.z());
  for (auto& t : m.triangles) std::swap(t[1], t[2]);
  const Eigen::Matrix3d R = Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  for (auto& p : m.vertices) p = R * p;
  return m;
}

}  // namespace mgsr
